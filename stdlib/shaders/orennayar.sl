/* orennayar — Oren–Nayar rough diffuse reflection (the qualitative model): a matte surface
 * whose facets have slope deviation `sigma` (radians).  sigma = 0 is Lambert; larger values
 * flatten the shading toward the limb (clay, plaster, the Moon). */
#include "reflectance.h"

surface orennayar(float Ka = 1; float Kd = 1; float sigma = 0.5;)
{
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    /* Kd·π·f is the albedo convention of diffuse(): Kd = 1 is a white Lambertian surface */
    Oi = Os;
    Ci = Os * Cs * (Ka * ambient() + Kd * PI * LocIllumOrenNayar(Nf, V, sigma));
}
