/* terrain — colours a landscape by altitude and slope (book §7.1's fractal terrain, Plate 21
 * style): water below `waterlevel`, then beach, grass, forest, rock and snow with altitude;
 * steep faces (slope = 1 − N·up) turn to rock whatever their height, and snow only settles
 * where it is flat enough.  Band edges are wobbled by band-limited fBm so they do not follow
 * contour lines exactly, and every transition is a filtered smoothstep over the footprint of
 * the altitude.  Altitude is measured along `up` in shading space, in the units of `P`,
 * between `minheight` and `maxheight`. */
#include "noises.h"

surface terrain(float Ka = 1; float Kd = 0.85; float Ks = 0.05; float roughness = 0.3;
                float minheight = 0; float maxheight = 1; float waterlevel = 0.12;
                float snowlevel = 0.72; float treeline = 0.55; float wobble = 0.06;
                vector up = vector(0, 1, 0);
                color water = color(0.08, 0.22, 0.42);
                color sand = color(0.76, 0.70, 0.50);
                color grass = color(0.30, 0.48, 0.16);
                color forest = color(0.12, 0.28, 0.10);
                color rock = color(0.42, 0.38, 0.34);
                color snow = color(0.95, 0.95, 0.98);
                string shadingspace = "shader"; float noisefreq = 8;)
{
    point PP = transform(shadingspace, P);
    vector upn = normalize(up);
    float h = ((PP - point(0, 0, 0)) . upn - minheight) / max(maxheight - minheight, 1.0e-6);
    point Q = PP * noisefreq;
    float fw = filterwidthp(Q);
    float n = fBm(Q, fw, 5, 2, 0.5);
    float hw = h + wobble * n;
    float dh = filterwidth(hw);
    normal Nw = normalize(ntransform(shadingspace, faceforward(normalize(N), I)));
    float slope = clamp(1 - abs(Nw . upn), 0, 1);
    color C = water;
    float dw = 0.015;
    color land = mix(sand, grass, filteredsmoothstep(waterlevel + dw, waterlevel + 3 * dw, hw, dh));
    land = mix(land, forest, filteredsmoothstep(0.3, 0.4, hw + 0.1 * n, dh) *
                                 (1 - filteredsmoothstep(treeline - 0.05, treeline, hw, dh)));
    land = mix(land, rock, filteredsmoothstep(treeline - 0.05, treeline + 0.05, hw, dh));
    /* steep faces are bare rock */
    land = mix(land, rock * (0.8 + 0.4 * (0.5 + 0.5 * n)), smoothstep(0.35, 0.55, slope + 0.1 * n));
    /* snow on the flatter high ground */
    float snowy = filteredsmoothstep(snowlevel - 0.03, snowlevel + 0.03, hw, dh) *
                  (1 - smoothstep(0.45, 0.65, slope));
    land = mix(land, snow, snowy);
    float wet = filteredsmoothstep(waterlevel, waterlevel + dw, h, filterwidth(h));
    C = mix(water * (0.8 + 0.2 * n), land, wet);
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    float spec = Ks + (1 - wet) * 0.5 + snowy * 0.1;
    Oi = Os;
    Ci = Os * (C * (Ka * ambient() + Kd * diffuse(Nf)) + spec * specular(Nf, V, roughness));
}
