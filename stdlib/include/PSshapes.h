/* PSshapes.h -- soft-edged shapes in texture space, with the interface of the header of the
 * same name in Peter Stuart's PS shaders (RenderMan Repository, 2002; built on Steve May's
 * RManNotes).  Written for arbor from the header's description, not a copy of it.
 * Each returns 1 inside the shape, 0 outside, with an edge fuzz wide.
 */
#ifndef PSSHAPES_H
#define PSSHAPES_H 1

#include "rmannotes.sl"

/* Area of the triangle p1 p2 p3 (half the length of the cross product of two sides). */
float tri_area (point p1, p2, p3;)
{
    return 0.5 * length((p2 - p1) ^ (p3 - p1));
}

/* A triangle by barycentric areas: the three sub-triangles of pt add up to the triangle's
 * area exactly inside it and to more outside; the excess, as a fraction of the area, is
 * faded out over fuzz. */
float bary_triangle (uniform point p1, p2, p3; float fuzz; point pt)
{
    float whole = tri_area(p1, p2, p3);
    float parts = tri_area(pt, p2, p3) + tri_area(p1, pt, p3) + tri_area(p1, p2, pt);
    return 1 - smoothstep(0, fuzz, parts / whole - 1);
}

/* The rectangle [left, right] x [top, bot]. */
float draw_rect (float left, right, top, bot, fuzz; float s, t)
{
    return intersection(pulse(left, right, fuzz, s), pulse(top, bot, fuzz, t));
}

/* A line from p1 to p2 (points in the (s, t, 0) plane) half_width wide on each side. */
float draw_line (point p1, p2; float fuzz, half_width, s, t;)
{
    float d = ptlined(p1, p2, point(s, t, 0));
    return 1 - smoothstep(half_width - fuzz, half_width, d);
}

/* A disc of the given radius about center. */
float draw_circle (point center; float radius, fuzz; float s, t;)
{
    float d = distance(center, point(s, t, 0));
    return 1 - smoothstep(radius - fuzz, radius, d);
}

/* A cone seen from above: 1 inside radius rad2, 0 outside rad1, a smooth ramp between (its
 * shoulders softened by fuzz, as a fraction of the ramp). */
float draw_cone (point center; float rad1, rad2, fuzz; float s, t;)
{
    float d = distance(center, point(s, t, 0));
    return 1 - smoothstep(fuzz, 1 - fuzz, (d - rad2) / (rad1 - rad2));
}

#endif /* PSSHAPES_H */
