/* blinnplastic — Blinn's half-vector variant of Phong (book L1519): ks (N·H)^n with
 * H = normalize(L + V) (E1).  n_Blinn ≈ 4·n_Phong matches phongplastic's highlight size,
 * hence the default exponent 80. */
#include "reflectance.h"

surface blinnplastic(float Ka = 1; float Kd = 0.7; float Ks = 0.3; float exponent = 80;
                     color specularcolor = 1;)
{
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    Oi = Os;
    Ci = Os * (Cs * (Ka * ambient() + Kd * diffuse(Nf)) +
               specularcolor * Ks * LocIllumBlinn(Nf, V, exponent));
}
