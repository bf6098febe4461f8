/* marble — veined marble (book §7.2.2, notes/shading.md §3.5):
 *   marble(P) = marble_colour(sin(veinfreq·x + turbamp·turbulence(P)))
 * with marble_colour a Catmull-Rom spline whose steep stretch makes thin dark veins.
 * Anti-aliasing: turbulence drops octaves finer than the footprint, and the sine is box
 * filtered analytically (sin x over a box of width w is sin x · sin(w/2)/(w/2)), so far-away
 * marble fades to its average colour instead of sparkling. */
#include "noises.h"

surface marble(float Ka = 1; float Kd = 0.8; float Ks = 0.4; float roughness = 0.08;
               color specularcolor = 1;
               color basecolor = color(0.92, 0.90, 0.86);
               color veincolor = color(0.18, 0.16, 0.22);
               float veinfreq = 3; float turbamp = 4; float octaves = 6;
               string shadingspace = "shader"; float shadingfreq = 1;)
{
    point PP = transform(shadingspace, P) * shadingfreq;
    float fw = filterwidthp(PP);
    float turb = turbulence(PP, fw, octaves, 2, 0.5);
    float x = veinfreq * xcomp(PP) + turbamp * turb;
    /* box-filtered sine: the footprint of x is its filter width */
    float dx = filterwidth(x);
    float sinc = 1;
    if (dx > 1.0e-4)
        sinc = sin(min(dx, PI) * 0.5) / (min(dx, PI) * 0.5) * (1 - smoothstep(PI * 0.5, PI, dx));
    float v = 0.5 + 0.5 * sin(x) * sinc;
    color mid = mix(basecolor, veincolor, 0.35);
    color Cm = spline(v, basecolor, basecolor, basecolor * 0.97, basecolor * 0.93, mid,
                      veincolor, basecolor * 0.9, basecolor, basecolor);
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    Oi = Os;
    Ci = Os * (Cm * (Ka * ambient() + Kd * diffuse(Nf)) +
               specularcolor * Ks * specular(Nf, V, roughness));
}
