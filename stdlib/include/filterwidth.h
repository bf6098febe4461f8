/* filterwidth.h — filter widths and box-filtered versions of the step-like functions, written
 * for arbor in the style of Advanced RenderMan (same names and argument orders).
 *
 * A filter width is how much a quantity changes across one micropolygon (the shading
 * footprint): |dx/du|·du + |dx/dv|·dv for a float, sqrt(area) for a point.  Every filtered*
 * function box-filters its unfiltered twin over [x − w/2, x + w/2] analytically (the integral
 * of the function divided by w), so a pattern built from them fades to its average instead of
 * aliasing when its features shrink below a micropolygon.
 */
#ifndef ARBOR_FILTERWIDTH_H
#define ARBOR_FILTERWIDTH_H 1

/* Smallest width returned, so that divisions by a width are always safe. */
#define MINFILTWIDTH 1.0e-6

/* Width of a float quantity across the footprint. */
#ifndef filterwidth   /* rmannotes.h, included first, defines the same */
#define filterwidth(x) max(abs(Du(x) * du) + abs(Dv(x) * dv), MINFILTWIDTH)
#endif

/* Width of a point (or vector) quantity: the square root of the area it sweeps. */
#define filterwidthp(p) max(sqrt(area(p)), MINFILTWIDTH)

/* Step of x past edge, box filtered by width w (step convolved with a box: a linear ramp). */
float filteredstep(float edge, x, w)
{
    return clamp((x - edge) / max(w, MINFILTWIDTH) + 0.5, 0, 1);
}

/* Pulse that is 1 on [edge0, edge1) and 0 elsewhere, box filtered by width w: the length of the
 * overlap of [x − w/2, x + w/2] with the pulse, over w. */
float filteredpulse(float edge0, edge1, x, w)
{
    float ww = max(w, MINFILTWIDTH);
    float x0 = x - 0.5 * ww;
    float x1 = x0 + ww;
    return max(0, min(x1, edge1) - max(x0, edge0)) / ww;
}

/* Integral from 0 to x of a period-1 pulse train that is 0 on [0, e) and 1 on [e, 1). */
#define ARBOR_PULSETRAIN_INTEGRAL(x, e) ((1 - (e)) * floor(x) + max(0, (x) - floor(x) - (e)))

/* Periodic pulse: 0 on [0, edge) and 1 on [edge, period) in every period, box filtered by w.
 * Once the filter covers a whole period the average, 1 − edge/period, is returned. */
float filteredpulsetrain(float edge, period, x, w)
{
    float invp = 1 / period;
    float fw = max(w, MINFILTWIDTH) * invp;
    float e = edge * invp;
    float x0 = x * invp - 0.5 * fw;
    float x1 = x0 + fw;
    float r = 1 - e;
    if (fw < 1)
        r = (ARBOR_PULSETRAIN_INTEGRAL(x1, e) - ARBOR_PULSETRAIN_INTEGRAL(x0, e)) / fw;
    return r;
}

/* |x| box filtered by w: the antiderivative of |x| is x·|x|/2. */
float filteredabs(float x, w)
{
    float ww = max(w, MINFILTWIDTH);
    float x0 = x - 0.5 * ww;
    float x1 = x + 0.5 * ww;
    return (x1 * abs(x1) - x0 * abs(x0)) / (2 * ww);
}

/* Antiderivative of smoothstep(0, 1, t): t³ − t⁴/2 on [0,1], 0 before, t − ½ after. */
float arbor_smoothstep_integral(float t)
{
    float r;
    if (t <= 0)
        r = 0;
    else if (t >= 1)
        r = t - 0.5;
    else
        r = t * t * t * (1 - 0.5 * t);
    return r;
}

/* smoothstep(e0, e1, x) box filtered by w. */
float filteredsmoothstep(float e0, e1, x, w)
{
    float ww = max(w, MINFILTWIDTH);
    float span = max(e1 - e0, MINFILTWIDTH);
    float t0 = (x - 0.5 * ww - e0) / span;
    float t1 = (x + 0.5 * ww - e0) / span;
    return (arbor_smoothstep_integral(t1) - arbor_smoothstep_integral(t0)) * span / ww;
}

/* Smooth pulse (1 between the middle edges, smoothstep ramps at either end), box filtered. */
float filteredsmoothpulse(float e0, e1, e2, e3, x, w)
{
    return filteredsmoothstep(e0, e1, x, w) - filteredsmoothstep(e2, e3, x, w);
}

/* floor(x) box filtered by w, via its antiderivative ⌊x⌋x − ⌊x⌋(⌊x⌋+1)/2. */
float arbor_floor_integral(float x)
{
    float f = floor(x);
    return f * x - 0.5 * f * (f + 1);
}

float filteredfloor(float x, w)
{
    float ww = max(w, MINFILTWIDTH);
    return (arbor_floor_integral(x + 0.5 * ww) - arbor_floor_integral(x - 0.5 * ww)) / ww;
}

/* mod(x, 1) box filtered (x − floor(x) filtered). */
float filteredmod1(float x, w)
{
    return x - filteredfloor(x, w);
}

/* A function g of known average g_avg whose finest features are featuresize across, faded to
 * the average as the filter width fwidth approaches them (Advanced RenderMan's fadeout). */
#define fadeout(g, g_avg, featuresize, fwidth) \
        mix((g), (g_avg), smoothstep(0.2, 0.6, (fwidth) / (featuresize)))

#endif
