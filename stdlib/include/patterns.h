/* patterns.h — basic pattern building blocks (pulses, steps, tiling, 2-D rotation), written for
 * arbor in the style of Advanced RenderMan (same names and argument orders).  The unfiltered
 * functions are here; their box-filtered twins (filteredpulse, filteredsmoothstep, …) are in
 * filterwidth.h, which this header includes.
 */
#ifndef ARBOR_PATTERNS_H
#define ARBOR_PATTERNS_H 1

#include "filterwidth.h"

/* 1 on [a, b), 0 elsewhere. */
float pulse(float a, b, x)
{
    return step(a, x) - step(b, x);
}

/* Periodic pulse: 0 on [0, edge) and 1 on [edge, period) of every period. */
float pulsetrain(float edge, period, x)
{
    return pulse(edge, period, mod(x, period));
}

/* Linear ramp from 0 at a to 1 at b, clamped. */
float boxstep(float a, b, x)
{
    return clamp((x - a) / (b - a), 0, 1);
}

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
#define repeat(x, freq) mod((x) * (freq), 1.0)
#define whichtile(x, freq) floor((x) * (freq))
#define odd(x) (mod((x), 2) == 1)
#define even(x) (mod((x), 2) == 0)

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

/* Box-filtered checkerboard of period 1 in s and t: 1 on "white" squares. */
float filteredchecker(float s, t, ds, dt)
{
    float a = filteredpulsetrain(0.5, 1, s, ds);
    float b = filteredpulsetrain(0.5, 1, t, dt);
    return a * b + (1 - a) * (1 - b);
}

#endif
