/* phongplastic — the Phong model as the book writes it (2.5):
 *   I = Ia·ka + Σ Ii [kd (N·L) + ks (R·V)^n],  R = 2(N·L)N − L,
 * with the specular term 0 when N·L ≤ 0 and the highlight in the light's colour. */
#include "reflectance.h"

surface phongplastic(float Ka = 1; float Kd = 0.7; float Ks = 0.3; float exponent = 20;
                     color specularcolor = 1;)
{
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    Oi = Os;
    Ci = Os * (Cs * (Ka * ambient() + Kd * diffuse(Nf)) +
               specularcolor * Ks * LocIllumPhong(Nf, V, exponent));
}
