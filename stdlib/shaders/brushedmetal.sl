/* brushedmetal — Ward's anisotropic model (bounded-albedo form) for brushed metal: the
 * highlight stretches across the brushing direction.  The brushing direction is `brushdir`
 * in shading space, or dPdu when brushdir is zero (brushed along u: circles on a disk or
 * sphere).  A little fine noise along the brush direction adds the scratches. */
#include "reflectance.h"
#include "noises.h"

surface brushedmetal(float Ka = 1; float Kd = 0.1; float Ks = 1;
                     float xroughness = 0.04; float yroughness = 0.25;
                     vector brushdir = vector(0, 0, 0); float scratches = 0.15;
                     color specularcolor = color(0.91, 0.92, 0.92); float Kr = 0.6;
                     string shadingspace = "shader";)
{
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    vector xdir = normalize(dPdu);
    if (length(brushdir) > 0)
        xdir = normalize(vtransform(shadingspace, "current", brushdir));
    /* scratches: noise stretched along the brush direction */
    point PP = transform(shadingspace, P);
    float u0 = (PP - point(0, 0, 0)) . normalize(vtransform("current", shadingspace, xdir));
    point Q = PP * 60 - 55 * u0 * normalize(vtransform("current", shadingspace, xdir));
    float sc = 1 + scratches * filteredsnoise(Q, filterwidthp(Q));
    /* the environment (a sky stand-in), smeared by the brushing toward its average */
    color env = fake_environment(vtransform("world", reflect(I, Nf)), color(0.35, 0.5, 0.85),
                                 color(0.95, 0.95, 0.92), color(0.2, 0.17, 0.14));
    env = mix(env, color(0.5, 0.52, 0.55), 0.5);
    Oi = Os;
    Ci = Os * (Kr * sc * specularcolor * env +Cs * (Ka * ambient() + Kd * diffuse(Nf)) * specularcolor * 0.3 +
               sc * specularcolor * Ks * LocIllumWardAnisotropic(Nf, V, xdir, xroughness, yroughness));
}
