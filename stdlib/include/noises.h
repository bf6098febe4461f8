/* noises.h — signed noise, band-limited noise and fractal sums (fBm, vector fBm, turbulence,
 * ridged multifractal, animated turbulence) and Worley/Voronoi cell noise, written for arbor
 * in the style of Advanced RenderMan (same names and argument orders).
 *
 * Anti-aliasing (notes/shading.md §3.4, book §4.8): octave i has frequency lacunarity^i and
 * filter width filtwidth·lacunarity^i in noise cells.  It is weighted by Peachey's ramp
 * w = clamp((½ − width)/¼, 0, 1): full below ¼ cycle per micropolygon, zero at the Nyquist
 * limit ½.  The octave loop stops at the first octave whose weight is zero (per point: the
 * loop condition is varying), so distant or small surfaces evaluate fewer octaves.  A faded
 * octave is replaced by its mean (0 for snoise, ARBOR_ABS_SNOISE_MEAN for |snoise|), which is
 * what a wide box filter returns.  This matches arbor's built-in pattern library
 * (src/pattern/fractal.rs), including the per-octave lattice offsets that keep the zeros of
 * successive octaves from lining up.
 */
#ifndef ARBOR_NOISES_H
#define ARBOR_NOISES_H 1

#include "filterwidth.h"
#include "patterns.h"   /* as in Advanced RenderMan: shaders expect its functions too */

/* Signed noise in [−1, 1]. */
#ifndef snoise   /* rmannotes.h and DPProctext.h define the same */
#define snoise(p) (2 * (float noise(p)) - 1)
#define snoise2(x, y) (2 * (float noise(x, y)) - 1)
#endif
#define snoisexy(x, y) (2 * (float noise(x, y)) - 1)
#define snoiset(p, t) (2 * (float noise(p, t)) - 1)
#define vsnoise(p) (2 * (vector noise(p)) - 1)
#define vsnoiset(p, t) (2 * (vector noise(p, t)) - 1)

/* Mean of |snoise| over space (measured; src/pattern/noise.rs ABS_SNOISE3_MEAN). */
#define ARBOR_ABS_SNOISE_MEAN 0.2116

/* Peachey's fade of a noise of feature size 1 under a filter of width w. */
#define arbor_octave_weight(w) clamp((0.5 - (w)) * 4, 0, 1)

/* Band-limited signed noise: fades to its mean 0 as the footprint reaches Nyquist. */
#define filteredsnoise(p, width) (snoise(p) * arbor_octave_weight(width))
#define filteredvsnoise(p, width) (vsnoise(p) * arbor_octave_weight(width))
#define filterednoise(p, width) (0.5 + 0.5 * filteredsnoise(p, width))

/* Offset decorrelating the lattice of octave i from octave 0. */
#define arbor_octave_offset(i) vector((i) * 17.31, (i) * -11.77, (i) * 7.13)

/* Fractional Brownian motion Σ gain^i · snoise(p · lacunarity^i), band limited. */
float fBm(point p; float filtwidth; uniform float octaves, lacunarity, gain)
{
    float sum = 0;
    float fw = filtwidth;
    float amp = 1;
    float freq = 1;
    float i = 0;
    while (i < octaves && fw < 0.5) {
        float w = arbor_octave_weight(fw) * min(1, octaves - i);
        sum += amp * w * snoise(p * freq + arbor_octave_offset(i));
        amp *= gain;
        freq *= lacunarity;
        fw *= lacunarity;
        i += 1;
    }
    return sum;
}

/* Vector fBm: three decorrelated fBm channels. */
vector vfBm(point p; float filtwidth; uniform float octaves, lacunarity, gain)
{
    vector sum = 0;
    float fw = filtwidth;
    float amp = 1;
    float freq = 1;
    float i = 0;
    while (i < octaves && fw < 0.5) {
        float w = arbor_octave_weight(fw) * min(1, octaves - i);
        sum += amp * w * vsnoise(p * freq + arbor_octave_offset(i));
        amp *= gain;
        freq *= lacunarity;
        fw *= lacunarity;
        i += 1;
    }
    return sum;
}

/* Turbulence (book L6875 with its abs): Σ gain^i · |snoise(p · lacunarity^i)|, in
 * [0, Σ gain^i].  Octaves beyond the footprint contribute their mean, so the average
 * brightness does not change with distance. */
float turbulence(point p; float filtwidth; uniform float octaves, lacunarity, gain)
{
    float sum = 0;
    float fw = filtwidth;
    float amp = 1;
    float freq = 1;
    float i = 0;
    while (i < octaves && fw < 0.5) {
        float w = arbor_octave_weight(fw);
        float frac = min(1, octaves - i);
        float v = abs(snoise(p * freq + arbor_octave_offset(i)));
        sum += amp * frac * (w * v + (1 - w) * ARBOR_ABS_SNOISE_MEAN);
        amp *= gain;
        freq *= lacunarity;
        fw *= lacunarity;
        i += 1;
    }
    /* the octaves the footprint removed entirely */
    while (i < octaves) {
        sum += amp * min(1, octaves - i) * ARBOR_ABS_SNOISE_MEAN;
        amp *= gain;
        i += 1;
    }
    return sum;
}

/* Animated turbulence over space and time (book §7.2.3): time is a fourth lattice axis,
 * scaled with each octave's frequency, and the pattern rises at `rise` units per unit time
 * (the book's convection term, L6942). */
float turbulencet(point p; float t; float filtwidth; uniform float octaves, lacunarity, gain;
                  float rise)
{
    point pp = p - vector(0, rise * t, 0);
    float sum = 0;
    float fw = filtwidth;
    float amp = 1;
    float freq = 1;
    float i = 0;
    while (i < octaves && fw < 0.5) {
        float w = arbor_octave_weight(fw);
        float frac = min(1, octaves - i);
        float v = abs(snoiset(pp * freq + arbor_octave_offset(i), t * freq));
        sum += amp * frac * (w * v + (1 - w) * ARBOR_ABS_SNOISE_MEAN);
        amp *= gain;
        freq *= lacunarity;
        fw *= lacunarity;
        i += 1;
    }
    while (i < octaves) {
        sum += amp * min(1, octaves - i) * ARBOR_ABS_SNOISE_MEAN;
        amp *= gain;
        i += 1;
    }
    return sum;
}

/* Musgrave's ridged multifractal: each octave is (offset − |snoise|)², weighted by the
 * previous octave's signal (clamped by `gain`) so ridges stay sharp and valleys smooth.
 * H sets the spectral exponent (amplitude lacunarity^(−H·i)); offset ≈ 1, gain ≈ 2.
 * Result is roughly in [0, 2]. */
float ridgedmultifractal(point p; float filtwidth; uniform float octaves, lacunarity, H,
                         offset, gain)
{
    float fw = filtwidth;
    float freq = 1;
    float signal = offset - abs(snoise(p));
    signal *= signal;
    float sum = signal * arbor_octave_weight(fw);
    float weight = 1;
    float i = 1;
    fw *= lacunarity;
    freq *= lacunarity;
    while (i < octaves && fw < 0.5) {
        weight = clamp(signal * gain, 0, 1);
        signal = offset - abs(snoise(p * freq + arbor_octave_offset(i)));
        signal *= signal * weight;
        sum += signal * pow(freq, -H) * arbor_octave_weight(fw) * min(1, octaves - i);
        freq *= lacunarity;
        fw *= lacunarity;
        i += 1;
    }
    return sum;
}

/* Worley/Voronoi cell noise: the distance f1 to the nearest of the feature points (one per
 * unit cell, jittered inside it by `jitter` ∈ [0,1]) and that point's position. */
void voronoi_f1_3d(point P; float jitter; output float f1; output point pos1)
{
    point thiscell = point(floor(xcomp(P)) + 0.5, floor(ycomp(P)) + 0.5, floor(zcomp(P)) + 0.5);
    f1 = 1000;
    uniform float i, j, k;
    for (i = -1; i <= 1; i += 1) {
        for (j = -1; j <= 1; j += 1) {
            for (k = -1; k <= 1; k += 1) {
                point testcell = thiscell + vector(i, j, k);
                point pos = testcell + jitter * (vector cellnoise(testcell) - 0.5);
                vector offset = pos - P;
                float dist = offset . offset;
                if (dist < f1) {
                    f1 = dist;
                    pos1 = pos;
                }
            }
        }
    }
    f1 = sqrt(f1);
}

/* The two nearest feature points: distances f1 ≤ f2 and their positions. */
void voronoi_f1f2_3d(point P; float jitter; output float f1; output point pos1;
                     output float f2; output point pos2)
{
    point thiscell = point(floor(xcomp(P)) + 0.5, floor(ycomp(P)) + 0.5, floor(zcomp(P)) + 0.5);
    f1 = 1000;
    f2 = 1000;
    uniform float i, j, k;
    for (i = -1; i <= 1; i += 1) {
        for (j = -1; j <= 1; j += 1) {
            for (k = -1; k <= 1; k += 1) {
                point testcell = thiscell + vector(i, j, k);
                point pos = testcell + jitter * (vector cellnoise(testcell) - 0.5);
                vector offset = pos - P;
                float dist = offset . offset;
                if (dist < f1) {
                    f2 = f1;
                    pos2 = pos1;
                    f1 = dist;
                    pos1 = pos;
                } else if (dist < f2) {
                    f2 = dist;
                    pos2 = pos;
                }
            }
        }
    }
    f1 = sqrt(f1);
    f2 = sqrt(f2);
}

/* Convenience: the F1 distance alone. */
float voronoi(point P; float jitter)
{
    float f1;
    point pos1;
    voronoi_f1_3d(P, jitter, f1, pos1);
    return f1;
}

/* ---- More of Advanced RenderMan's noises.h interface ---------------------------------- */

/* The usual settings: 4 octaves, lacunarity 2, gain 1/2, filtered over p's footprint. */
#define fBm_default(p) fBm((p), filterwidthp(p), 4, 2, 0.5)
#define vfBm_default(p) vfBm((p), filterwidthp(p), 4, 2, 0.5)
#define turbulence_default(p) turbulence((p), filterwidthp(p), 4, 2, 0.5)

/* Ken Musgrave's "variable lacunarity" noise: noise at a point displaced by vector noise
 * (scale sets how far), which breaks up the lattice's regularity. */
#define VLNoise(Pt, scale) (snoise(vsnoise(Pt) * (scale) + (Pt)))
#define filteredVLNoise(Pt, fwidth, scale) \
        (filteredsnoise(filteredvsnoise((Pt), (fwidth)) * (scale) + (Pt), (fwidth)))

/* fBm of VLNoise: octave i is filteredVLNoise at p·lacunarity^i weighted gain^i. */
float VLfBm(point p; float filtwidth; uniform float octaves, lacunarity, gain, scale)
{
    float sum = 0;
    float fw = filtwidth;
    point pp = p;
    uniform float amp = 1;
    uniform float i;
    for (i = 0; i < octaves; i += 1) {
        sum += amp * filteredVLNoise(pp, fw, scale);
        amp *= gain;
        pp *= lacunarity;
        fw *= lacunarity;
    }
    return sum;
}

#define VLfBm_default(p) VLfBm((p), filterwidthp(p), 4, 2, 0.5, 1.0)

/* BMRT's noises.h fBm: octaves of band-limited snoise (gain^i, lacunarity^i) until
 * maxoctaves or until an octave's footprint reaches a whole noise cell. */
float filtered_fBm(point p; float filtwidth; uniform float maxoctaves, lacunarity, gain)
{
    float sum = 0;
    float fw = filtwidth;
    point pp = p;
    float amp = 1;
    float i = 0;
    while (i < maxoctaves && fw < 1) {
        sum += amp * filteredsnoise(pp, fw);
        amp *= gain;
        pp *= lacunarity;
        fw *= lacunarity;
        i += 1;
    }
    return sum;
}

#define filtered_fBm_default(p) filtered_fBm((p), sqrt(area(p)), 4, 2, 0.5)

#endif
