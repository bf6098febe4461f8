/* flame — an animated flame on a rectangle (book §7.2.3, notes/shading.md §3.6):
 *   flame(x, t) = (1 − y/h) · flame_colour(|x/b|) + turbulence(x + (0, t·rise, 0), t)
 * over s ∈ [0,1] (across, centre 0.5) and t ∈ [0,1] (bottom to top).  flame_colour is three
 * splines with their maximum at 0 that reach 0 at 1, green and blue falling off sooner than
 * red.  Turbulence is 4-D (time is a lattice axis) and convected upward; time comes from the
 * `time` global unless `frametime` ≥ 0.  Emissive, with matching opacity. */
#include "noises.h"

surface flame(float intensity = 1.6; float turbamp = 0.55; float rise = 1.5;
              float freq = 5; float octaves = 5; float frametime = -1; float width = 0.5;)
{
    float T = frametime >= 0 ? frametime : time;
    float x = (s - 0.5) / width;
    float y = 1 - t; /* v runs downward on most swatches: t = 0 at the top */
    point Q = point(x * freq * 0.5, y * freq, 0);
    float fw = filterwidthp(Q);
    float turb = turbulencet(Q, T, fw, octaves, 2, 0.5, rise) - 0.35;
    /* the turbulence displaces the lookup, narrowing and licking the flame */
    float ax = clamp(abs(x) + turbamp * turb * 0.6 * (0.3 + y), 0, 1);
    float fall = clamp(1 - y + turbamp * turb * 0.5, 0, 1);
    float r = spline(ax, 1, 1, 0.95, 0.7, 0.3, 0, 0);
    float g = spline(ax, 0.9, 0.9, 0.6, 0.2, 0, 0, 0);
    float b = spline(ax, 0.6, 0.6, 0.15, 0, 0, 0, 0);
    color Cf = intensity * fall * color(r, g * (0.4 + 0.6 * fall), b * fall);
    float a = clamp(fall * r * 1.2, 0, 1);
    Oi = a;
    Ci = Cf * a;
}
