/* torrancesparrow — the Torrance–Sparrow model (book §2.5): Gaussian distribution of facet
 * angles (normalised), V-groove masking/shadowing G, and the dielectric Fresnel term of index
 * eta, over a Lambert diffuse base: a glossy plastic or paint whose highlight brightens and
 * shifts off-specular at grazing angles. */
#include "reflectance.h"

surface torrancesparrow(float Ka = 1; float Kd = 0.6; float Ks = 1; float roughness = 0.25;
                        float eta = 1.5; color specularcolor = 1;)
{
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    Oi = Os;
    Ci = Os * (Cs * (Ka * ambient() + Kd * diffuse(Nf)) +
               specularcolor * Ks * LocIllumTorranceSparrow(Nf, V, roughness, eta));
}
