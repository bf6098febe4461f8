/* patterns.h — basic pattern building blocks (pulses, steps, tiling, 2-D rotation), written for
 * arbor in the style of Advanced RenderMan (same names and argument orders).  The unfiltered
 * functions are here; their box-filtered twins (filteredpulse, filteredsmoothstep, …) are in
 * filterwidth.h, which this header includes.
 */
#ifndef ARBOR_PATTERNS_H
#define ARBOR_PATTERNS_H 1

#include "filterwidth.h"

/* 1 on [a, b), 0 elsewhere. */
#ifndef pulse   /* rmannotes.h, included first, has a four-argument pulse macro */
float pulse(float a, b, x)
{
    return step(a, x) - step(b, x);
}
#endif

/* Periodic pulse: 0 on [0, edge) and 1 on [edge, period) of every period. */
float pulsetrain(float edge, period, x)
{
    float m = mod(x, period);
    return step(edge, m) - step(period, m);
}

/* Linear ramp from 0 at a to 1 at b, clamped. */
#ifndef boxstep
float boxstep(float a, b, x)
{
    return clamp((x - a) / (b - a), 0, 1);
}
#endif

/* Rises smoothly over [e0, e1], stays 1, falls smoothly over [e2, e3]. */
float smoothpulse(float e0, e1, e2, e3, x)
{
    return smoothstep(e0, e1, x) - smoothstep(e2, e3, x);
}

float smoothpulsetrain(float e0, e1, e2, e3, period, x)
{
    return smoothpulse(e0, e1, e2, e3, mod(x, period));
}

/* Tiling: the position inside the current tile, which tile, and parity. */
#ifndef repeat   /* rmannotes.h and patterns.h both define these four */
#define repeat(x, freq) mod((x) * (freq), 1.0)
#define whichtile(x, freq) floor((x) * (freq))
#define odd(x) (mod((x), 2) == 1)
#define even(x) (mod((x), 2) == 0)
#endif

/* Position within a tile of size (tilewidth, tileheight) and the tile's index: the arbor
 * `tile` helper used by brick- and checker-like shaders. */
void tile(float x, y, tilewidth, tileheight; output float ss, tt, col, row)
{
    col = floor(x / tilewidth);
    row = floor(y / tileheight);
    ss = x / tilewidth - col;
    tt = y / tileheight - row;
}

/* Rotate (x, y) by rad around (ox, oy). */
#ifndef rotate2d   /* rmannotes.h has macro versions of these two */
void rotate2d(float x, y, rad, ox, oy; output float rx, ry)
{
    float sa = sin(rad);
    float ca = cos(rad);
    rx = ox + (x - ox) * ca - (y - oy) * sa;
    ry = oy + (x - ox) * sa + (y - oy) * ca;
}

/* Polar coordinates (radius, angle) of (x, y). */
void topolar2d(float x, y; output float r, theta)
{
    r = sqrt(x * x + y * y);
    theta = atan(y, x);
}
#endif

/* Box-filtered checkerboard of period 1 in s and t: 1 on "white" squares. */
float filteredchecker(float s, t, ds, dt)
{
    float a = filteredpulsetrain(0.5, 1, s, ds);
    float b = filteredpulsetrain(0.5, 1, t, dt);
    return a * b + (1 - a) * (1 - b);
}

/* ---- More of Advanced RenderMan's patterns.h interface (ch. 11-12) -------------------- */

/* x squared. */
float sqr(float x)
{
    return x * x;
}

/* A colour varied per tile (or any integer index): the hue shifted by up to ±varyhue/2 of a
 * turn, saturation and lightness scaled by 1 ± varysat/2 and 1 ± varylum/2, each by its own
 * cellnoise of the index, so every tile gets a fixed variation of the base colour.  The cells
 * are the book's (index + 3, index - 14, index + 37): a scene varies its tiles the same way
 * with this header as with the book's. */
color varyEach(color Cin; float index, varyhue, varysat, varylum;)
{
    color hsl = ctransform("hsl", Cin);
    float h = comp(hsl, 0) + varyhue * (float cellnoise(index + 3) - 0.5);
    float sat = comp(hsl, 1) * (1 - varysat * (float cellnoise(index - 14) - 0.5));
    float lum = comp(hsl, 2) * (1 - varylum * (float cellnoise(index + 37) - 0.5));
    color varied = color(mod(h, 1), clamp(sat, 0, 1), clamp(lum, 0, 1));
    return ctransform("hsl", "rgb", varied);
}

/* Unit tiles separated by grooves groovewidth wide in s and grooveheight in t, centred on
 * the integer lines: which tile (ss, tt) is in, where inside it (0..1), and the box-filtered
 * (widths ds, dt) fraction of the footprint on the tile rather than in a groove. */
float tilepattern(float ss, tt, ds, dt; float groovewidth, grooveheight;
                  output float swhichtile, twhichtile; output float stile, ttile;)
{
    swhichtile = floor(ss);
    twhichtile = floor(tt);
    stile = ss - swhichtile;
    ttile = tt - twhichtile;
    float ins = filteredpulsetrain(groovewidth, 1, ss + 0.5 * groovewidth, ds);
    float intt = filteredpulsetrain(grooveheight, 1, tt + 0.5 * grooveheight, dt);
    return ins * intt;
}

/* Brick rows: tiles of tilewidth x tileheight, each row shifted by rowstagger (a fraction of
 * a tile) more than the one below, plus up to ±rowstaggervary/2 of noise per row; edges made
 * irregular by noise of frequency jaggedfreq (per tile) and amplitude jaggedamp.  Returns the
 * brick (column, row) and the position inside it (xtile, ytile in 0..1). */
void basicbrick(float x, y; uniform float tilewidth, tileheight;
                uniform float rowstagger, rowstaggervary;
                uniform float jaggedfreq, jaggedamp;
                output float column, row; output float xtile, ytile;)
{
    float sx = x, sy = y;
    if (jaggedamp != 0) {
        point wobble = point noise(x * jaggedfreq / tilewidth, y * jaggedfreq / tileheight);
        sx += jaggedamp * xcomp(wobble);
        sy += jaggedamp * ycomp(wobble);
    }
    float bx = sx / tilewidth, by = sy / tileheight;
    row = floor(by);
    bx += mod(rowstagger * row, 1) + rowstaggervary * (float noise(row + 0.5) - 0.5);
    column = floor(bx);
    xtile = bx - column;
    ytile = by - row;
}

/* BMRT's patterns.h name for the same brick pattern. */
void basictile(float x, y; uniform float tilewidth, tileheight;
               uniform float rowstagger, rowstaggervary;
               uniform float jaggedfreq, jaggedamp;
               output float column, row; output float xtile, ytile;)
{
    basicbrick(x, y, tilewidth, tileheight, rowstagger, rowstaggervary, jaggedfreq, jaggedamp,
               column, row, xtile, ytile);
}

#endif
