/* wood — solid wood rings (book §7.2, notes/shading.md §3.2): concentric cylinders around the
 * shading-space z axis, wobbled by r2 = r1 + a·sin(kθ) and twisted along the axis by
 * r3 = r2 + a·sin(kθ + z/b), plus a little fBm grain; a point is dark latewood where
 * frac(r3·ringfreq) ≥ 1 − latewood.  The ring pulse train is box filtered
 * (filteredpulsetrain), so rings finer than a micropolygon blend to their average. */
#include "noises.h"

surface wood(float Ka = 1; float Kd = 0.75; float Ks = 0.25; float roughness = 0.12;
             color specularcolor = 1;
             color lightwood = color(0.78, 0.52, 0.28);
             color darkwood = color(0.42, 0.22, 0.09);
             float ringfreq = 6; float latewood = 0.3; float wobble = 0.06;
             float wobblefreq = 8; float twist = 4; float grain = 0.08;
             string shadingspace = "shader"; float shadingfreq = 1;)
{
    point PP = transform(shadingspace, P) * shadingfreq;
    float fw = filterwidthp(PP);
    float x = xcomp(PP);
    float y = ycomp(PP);
    float z = zcomp(PP);
    float r1 = sqrt(x * x + y * y);
    float theta = atan(y, x);
    float r3 = r1 + wobble * (sin(wobblefreq * theta) + sin(wobblefreq * theta + z / twist)) / ringfreq
               + grain * fBm(PP * vector(4, 4, 0.5), fw * 4, 4, 2, 0.5) / ringfreq;
    float rr = r3 * ringfreq;
    float dr = filterwidth(rr);
    float late = filteredpulsetrain(1 - latewood, 1, rr, dr);
    /* fine streaks along the axis */
    float streak = 0.5 + 0.5 * filteredsnoise(PP * vector(40, 40, 1), fw * 40);
    color Cw = mix(lightwood, darkwood, late) * (0.85 + 0.3 * streak);
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    Oi = Os;
    Ci = Os * (Cw * (Ka * ambient() + Kd * diffuse(Nf)) +
               specularcolor * Ks * (1 - 0.5 * late) * specular(Nf, V, roughness));
}
