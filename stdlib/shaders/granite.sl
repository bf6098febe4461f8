/* granite — crystalline stone: Voronoi grains (one feature point per cell) each coloured from
 * a palette of quartz, feldspar and mica by its cell's random number, darkened along the grain
 * boundaries, with fine turbulent speckle.  Anti-aliasing: once a grain is smaller than about
 * two micropolygons the grains fade to the palette's average (and the speckle drops octaves
 * with the footprint), so distant granite is an even grey-pink, not noise. */
#include "noises.h"

surface granite(float Ka = 1; float Kd = 0.8; float Ks = 0.3; float roughness = 0.06;
                color specularcolor = 1;
                color quartz = color(0.80, 0.78, 0.76);
                color feldspar = color(0.72, 0.45, 0.38);
                color mica = color(0.08, 0.08, 0.09);
                color greyquartz = color(0.45, 0.45, 0.47);
                float grainsize = 0.08; float jitter = 1;
                string shadingspace = "shader"; float shadingfreq = 1;)
{
    point PP = transform(shadingspace, P) * shadingfreq / grainsize;
    float fw = filterwidthp(PP);
    float f1, f2;
    point p1, p2;
    voronoi_f1f2_3d(PP, jitter, f1, p1, f2, p2);
    float pick = float cellnoise(p1);
    color Cg;
    if (pick < 0.35)
        Cg = quartz;
    else if (pick < 0.65)
        Cg = feldspar;
    else if (pick < 0.82)
        Cg = greyquartz;
    else
        Cg = mica;
    /* grain boundaries where the two nearest points are nearly equidistant */
    float edge = 1 - 0.5 * (1 - filteredsmoothstep(0, 0.08, f2 - f1, fw));
    Cg *= edge;
    color avg = 0.35 * quartz + 0.30 * feldspar + 0.17 * greyquartz + 0.18 * mica;
    Cg = mix(Cg, avg * 0.95, smoothstep(0.2, 0.6, fw));
    float speck = turbulence(PP * 6, fw * 6, 4, 2, 0.5);
    Cg *= 0.8 + 0.4 * speck;
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    Oi = Os;
    Ci = Os * (Cg * (Ka * ambient() + Kd * diffuse(Nf)) +
               specularcolor * Ks * specular(Nf, V, roughness));
}
