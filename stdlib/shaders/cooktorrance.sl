/* cooktorrance — Cook–Torrance (book §2.6): ambient + Lambert + F·D·G microfacet specular with
 * the Beckmann distribution (normalised, E3), Torrance–Sparrow V-groove G, and the full
 * Fresnel term.  Name a metal ("gold", "silver", "copper", "aluminium", "iron") to use its
 * complex index n + ik with the exact conductor Fresnel; otherwise the book's RGB procedure
 * derives an index per channel from the normal reflectance F0 (0.04 = glass/plastic).  Metals
 * have no diffuse term (Kd = 0, as in Plate 3), and their highlights go white at grazing
 * angles.  Kr adds a Fresnel-weighted reflection of an environment map (envname) or, without
 * one, of a simple sky gradient. */
#include "reflectance.h"

surface cooktorrance(float Ka = 1; float Kd = 0; float Ks = 1; float roughness = 0.3;
                     string metal = "gold"; color F0 = color(0.04, 0.04, 0.04);
                     float Kr = 0.5; string envname = "";)
{
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    color n = 1, k = 0;
    float conductor = metal_nk(metal, n, k);
    color spec;
    color Fv;
    float cv = max(Nf . V, 0);
    if (conductor > 0) {
        spec = LocIllumCookTorranceNK(Nf, V, roughness, n, k);
        Fv = fresnel_conductor_rgb(cv, n, k);
    } else {
        color f0 = metal_F0(metal, F0);
        spec = LocIllumCookTorrance(Nf, V, roughness, f0);
        Fv = fresnel_rgb(cv, f0);
    }
    color Cr = 0;
    if (Kr > 0) {
        vector R = reflect(I, Nf);
        if (envname != "")
            Cr = color environment(envname, vtransform("world", R));
        else
            Cr = fake_environment(vtransform("world", R), color(0.35, 0.5, 0.85),
                                  color(0.95, 0.95, 0.92), color(0.2, 0.17, 0.14));
        /* rougher surfaces blur the reflection toward its average */
        Cr = mix(Cr, color(0.5, 0.55, 0.6), smoothstep(0.05, 0.5, roughness));
    }
    Oi = Os;
    Ci = Os * (Cs * (Ka * ambient() + Kd * diffuse(Nf)) + Ks * spec + Kr * Fv * Cr);
}
