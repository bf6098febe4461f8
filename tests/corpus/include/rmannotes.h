/* arbor test shim (not part of any shader collection): the helpers of Steve May's RManNotes
 * `rmannotes.sl`, written for this test from their documented meaning, so shaders that
 * include it compile. Shading-language semantics only; no code of the original. */
#ifndef ARBOR_RMANNOTES_SHIM_H
#define ARBOR_RMANNOTES_SHIM_H 1

/* 1 on [a, b), with soft edges of width fuzz ending at a and at b */
#define pulse(a, b, fuzz, x) \
    (smoothstep((a) - (fuzz), (a), (x)) - smoothstep((b) - (fuzz), (b), (x)))
/* position inside the current tile and the tile number, freq tiles per unit */
#ifndef repeat
#define repeat(x, freq) (mod((x) * (freq), 1.0))
#endif
#ifndef whichtile
#define whichtile(x, freq) (floor((x) * (freq)))
#endif
#define odd(x) (mod((x), 2) == 1)
#define even(x) (mod((x), 2) == 0)
/* (rx, ry) = (x, y) turned by rad radians about (ox, oy) */
#define rotate2d(x, y, rad, ox, oy, rx, ry) \
    rx = ((x) - (ox)) * cos(rad) - ((y) - (oy)) * sin(rad) + (ox); \
    ry = ((x) - (ox)) * sin(rad) + ((y) - (oy)) * cos(rad) + (oy)
/* polar coordinates of (x, y): radius and angle in [-PI, PI] */
#define topolar2d(x, y, r, theta) \
    r = sqrt((x) * (x) + (y) * (y)); \
    theta = atan(y, x)
/* fuzzy set operations on coverage values */
#define intersection(a, b) ((a) * (b))
#define union(a, b) ((a) + (b) - (a) * (b))
#define difference(a, b) ((a) - (a) * (b))
#define complement(a) (1 - (a))
/* linear blend that also takes colours as the third argument */
#define blend(a, b, x) ((a) * (1 - (x)) + (b) * (x))
#define lerp(a, b, x) ((a) * (1 - (x)) + (b) * (x))

#endif
