/* glass — a clear dielectric without ray tracing: reflection and refraction weighted by the
 * Fresnel terms (fresnel(): Kr + Kt = 1), each looked up in an environment map (envname) or,
 * without one, in a sky-gradient stand-in; plus a sharp highlight.  The refracted ray is
 * bent by eta and tinted by `transmitcolor`; total internal reflection sends everything to
 * the reflection.  Opaque in the hider (the see-through look comes from the environment). */
#include "reflectance.h"

surface glass(float Ka = 0; float Kd = 0; float Ks = 0.8; float roughness = 0.03;
              float Kr = 1; float Kt = 1; float eta = 1.5;
              color transmitcolor = color(0.92, 0.97, 0.95);
              string envname = "";
              color skycolor = color(0.35, 0.5, 0.85); color horizoncolor = color(0.95, 0.95, 0.9);
              color groundcolor = color(0.2, 0.17, 0.14);)
{
    normal Nn = normalize(N);
    vector In = normalize(I);
    normal Nf = faceforward(Nn, In);
    vector V = -In;
    /* entering when I runs against N, leaving otherwise */
    float ratio = (In . Nn) < 0 ? 1 / eta : eta;
    float kr, kt;
    vector R, T;
    fresnel(In, Nf, ratio, kr, kt, R, T);
    color Crefl, Crefr;
    if (envname != "") {
        Crefl = color environment(envname, vtransform("world", R));
        Crefr = color environment(envname, vtransform("world", T));
    } else {
        Crefl = fake_environment(vtransform("world", R), skycolor, horizoncolor, groundcolor);
        Crefr = fake_environment(vtransform("world", T), skycolor, horizoncolor, groundcolor);
    }
    if (length(T) == 0)
        kr = 1;
    Oi = 1;
    Ci = Kr * kr * Crefl + Kt * (1 - kr) * transmitcolor * Crefr +
         Cs * (Ka * ambient() + Kd * diffuse(Nf)) + Ks * specular(Nf, V, roughness);
}
