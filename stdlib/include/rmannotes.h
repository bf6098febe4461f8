/* rmannotes.h -- arbor's version of the pattern-building helpers that Steve May's "RManNotes"
 * tutorial defines and that many published shaders include.  Written for arbor from the
 * tutorial's description of each helper (not a copy of its file).
 *
 * Conventions: "layers" are built with a colour and an opacity and combined with blend();
 * opacities combine like sets (union, intersection, difference, complement).  All helpers
 * are macros, so they work for floats and colours alike and rotate2d/topolar2d can write
 * their results into the variables given.
 */
#ifndef RMANNOTES_H
#define RMANNOTES_H 1

/* 1 between a and b, 0 outside, with edges softened over fuzz (the edge starts fuzz before
 * a and before b). */
#define pulse(a, b, fuzz, x) (smoothstep((a) - (fuzz), (a), (x)) - \
                              smoothstep((b) - (fuzz), (b), (x)))

/* The same pulse under the name the RenderMan Repository's copy of the header gives it (it
 * renamed it so as not to clash with patterns.h's three-argument pulse). */
#define smoothPulse(a, b, fuzz, x) pulse(a, b, fuzz, x)

/* 0 below a, 1 above b, a straight ramp between. */
#ifndef boxstep
#define boxstep(a, b, x) clamp(((x) - (a)) / ((b) - (a)), 0, 1)
#endif

/* Tiling: position within the current tile, and which tile (frequency = tiles per unit). */
#ifndef repeat   /* rmannotes.h and patterns.h both define these four */
#define repeat(x, freq) (mod((x) * (freq), 1.0))
#define whichtile(x, freq) (floor((x) * (freq)))
#define odd(x) (mod((x), 2) == 1)
#define even(x) (mod((x), 2) == 0)
#endif

/* Layer compositing: b over a with opacity x (lerp is the same). */
#define blend(a, b, x) ((a) * (1 - (x)) + (b) * (x))
#define lerp(a, b, x) ((a) * (1 - (x)) + (b) * (x))

/* Signed noise in [-1, 1] (unless noises.h or another header defined it already). */
#ifndef snoise
#define snoise(x) (2 * (float noise(x)) - 1)
#define snoise2(x, y) (2 * (float noise(x, y)) - 1)
#endif

/* Noise spread more evenly over [lo, hi] (the middle half of noise's range stretched). */
#define udn(x, lo, hi) (smoothstep(0.25, 0.75, noise(x)) * ((hi) - (lo)) + (lo))
#define udn2(x, y, lo, hi) (smoothstep(0.25, 0.75, noise(x, y)) * ((hi) - (lo)) + (lo))

/* Footprint sizes (after Apodaca's 1992 course notes), unless filterwidth.h defined them. */
#ifndef MINFILTERWIDTH
#define MINFILTERWIDTH 1e-7
#define MINDERIV 0.0003
#endif
#ifndef filterwidth
#define filterwidth(x) max(abs(Du(x) * du) + abs(Dv(x) * dv), MINFILTERWIDTH)
#endif
#ifndef filterwidth_point
#define filterwidth_point(p) max(sqrt(area(p)), MINFILTERWIDTH)
#endif

/* Opacities as sets. */
#define union(a, b) ((a) + (b) - (a) * (b))
#define intersection(a, b) ((a) * (b))
#define difference(a, b) ((a) - (a) * (b))
#define complement(a) (1 - (a))

/* Box-filtered pulse: the fraction of [x - dx/2, x + dx/2] that lies inside [edge0, edge1]. */
float filteredpulse(float edge0, edge1, x, dx)
{
    float w = max(dx, 1e-6);
    float x0 = x - w / 2;
    float x1 = x0 + w;
    return max(0, (min(x1, edge1) - max(x0, edge0)) / w);
}

/* Rotates (x, y) by rad radians about (ox, oy), writing the result to (rx, ry). */
#define rotate2d(x, y, rad, ox, oy, rx, ry) \
    { \
        float rmn_c = cos(rad), rmn_s = sin(rad); \
        float rmn_x = (x) - (ox), rmn_y = (y) - (oy); \
        rx = rmn_x * rmn_c - rmn_y * rmn_s + (ox); \
        ry = rmn_x * rmn_s + rmn_y * rmn_c + (oy); \
    }

/* Cartesian (x, y) to polar: r the distance from the origin, theta the angle in
 * [0, 2*PI) counter-clockwise from +x. */
#define topolar2d(x, y, r, theta) \
    { \
        r = sqrt((x) * (x) + (y) * (y)); \
        theta = atan((y), (x)); \
        if (theta < 0) theta += 2 * PI; \
    }

#endif /* RMANNOTES_H */
