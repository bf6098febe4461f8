/* clouds — a sky of fBm clouds (book §7.2.2: turbulated texture for clouds).  Density is the
 * band-limited fBm thresholded by `coverage` and softened by `softness`; the sky colour
 * deepens toward the zenith (shading-space +y) when `gradient` > 0.  Emissive: the clouds are
 * not lit, so the surface can be a backdrop or a sky dome.  With `transparentsky` set, the
 * sky itself is transparent (Oi = density) for a cloud layer over a planet. */
#include "noises.h"

surface clouds(color skycolor = color(0.25, 0.45, 0.85);
               color horizoncolor = color(0.7, 0.8, 0.95);
               color cloudcolor = color(1, 1, 1);
               color shadowcolor = color(0.6, 0.63, 0.7);
               float coverage = 0.45; float softness = 0.35; float octaves = 7;
               float gradient = 1; float transparentsky = 0; float Kc = 1;
               string shadingspace = "shader"; float shadingfreq = 1;)
{
    point PP = transform(shadingspace, P) * shadingfreq;
    float fw = filterwidthp(PP);
    float f = 0.5 + 0.5 * fBm(PP, fw, octaves, 2, 0.5);
    float density = smoothstep(1 - coverage - 0.5 * softness, 1 - coverage + 0.5 * softness, f);
    /* thicker cloud is darker underneath: shade by a second, offset fBm sample */
    float f2 = 0.5 + 0.5 * fBm(PP + vector(0.07, 0.11, 0), fw, octaves, 2, 0.5);
    color Cc = mix(cloudcolor, shadowcolor, clamp((f2 - f) * 4 + 0.3 * density, 0, 1));
    vector up = normalize(vtransform(shadingspace, N));
    float h = clamp(abs(ycomp(normalize(transform(shadingspace, P)))), 0, 1);
    color Csky = mix(horizoncolor, skycolor, gradient > 0 ? pow(h, 0.6) : 1);
    if (transparentsky > 0) {
        Oi = density;
        Ci = Kc * Cc * density;
    } else {
        Oi = 1;
        Ci = Kc * mix(Csky, Cc, density);
    }
}
