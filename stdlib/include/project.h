/* project.h -- texture projections, with the interface of the header of the same name in
 * Advanced RenderMan (Apodaca & Gritz, 2000, ch. 8): spherical_projection,
 * cylindrical_projection, ProjectTo2D, Get{Color,Float}TextureAndAlpha,
 * Apply{Color,Float}TextureOver and array_to_mx.  Written for arbor from the book's
 * description, not a copy of its file.
 *
 * Projection names: "st" (the surface's s, t), "planar" (x, y), "perspective" (x/z, y/z),
 * "spherical" (longitude, latitude about the origin), "cylindrical" (longitude about the z
 * axis, height z).  The point is first taken to the named space and then through xform
 * (for "st": the point (s, t, 0) through xform).
 */
#ifndef PROJECT_H
#define PROJECT_H 1

#include "filterwidth.h"

/* The filter width of a coordinate that wraps at 1: a jump of more than half a period across
 * one micropolygon is the seam, and the real change is the rest of the period. */
float arbor_wrapped_width (float x)
{
    float w = filterwidth(x);
    if (w > 0.5)
        w = max(1 - w, MINFILTWIDTH);
    return w;
}

/* The angle of (x, y) about the z axis, as a fraction of a turn: 0.5 on +x, 0.25 on +y,
 * 0.75 on -y, 0 (or 1) on -x; it increases clockwise seen from +z. */
float arbor_longitude (vector V)
{
    return 0.5 - atan(ycomp(V), xcomp(V)) / (2 * PI);
}

/* Onto the unit sphere about the origin: ss = longitude, tt = latitude / pi, from -0.5 at
 * the -z pole through 0 at the equator to 0.5 at the +z pole. */
void spherical_projection (point p; output float ss, tt, ds, dt;)
{
    extern float du, dv;
    vector V = normalize(vector p);
    ss = arbor_longitude(V);
    tt = asin(clamp(zcomp(V), -1, 1)) / PI;
    ds = arbor_wrapped_width(ss);
    dt = arbor_wrapped_width(tt);
}

/* Onto the cylinder about the z axis: ss = longitude, tt = z (0..1 spans z = 0..1). */
void cylindrical_projection (point p; output float ss, tt, ds, dt;)
{
    extern float du, dv;
    ss = arbor_longitude(vector p);
    tt = zcomp(p);
    ds = arbor_wrapped_width(ss);
    dt = filterwidth(tt);
}

/* 2-D texture coordinates (ss, tt) and their filter widths (ds, dt) for P by the named
 * projection, after taking P to whichspace and through xform.  An unknown projection name
 * leaves the outputs as they were. */
void ProjectTo2D (string projection; point P; string whichspace; matrix xform;
                  output float ss, tt; output float ds, dt;)
{
    extern float du, dv;
    point Pp;
    if (projection == "st") {
        extern float s, t;
        Pp = point(s, t, 0);
    } else {
        Pp = transform(whichspace, P);
    }
    Pp = transform(xform, Pp);
    if (projection == "st" || projection == "planar") {
        ss = xcomp(Pp);
        tt = ycomp(Pp);
        ds = filterwidth(ss);
        dt = filterwidth(tt);
    } else if (projection == "perspective") {
        float depth = max(zcomp(Pp), 1.0e-6);
        ss = xcomp(Pp) / depth;
        tt = ycomp(Pp) / depth;
        ds = filterwidth(ss);
        dt = filterwidth(tt);
    } else if (projection == "spherical") {
        spherical_projection(Pp, ss, tt, ds, dt);
    } else if (projection == "cylindrical") {
        cylindrical_projection(Pp, ss, tt, ds, dt);
    }
}

/* The texture over the projected footprint (a box of the projected widths around (ss, tt)),
 * and its channel alphachannel as alpha (1 where the map has no such channel). */
color GetColorTextureAndAlpha (string texturename; string projection; point P;
                               string whichspace; matrix xform; float blur;
                               uniform float alphachannel; output float alpha;)
{
    float ss = 0, tt = 0, ds = 0, dt = 0;
    ProjectTo2D(projection, P, whichspace, xform, ss, tt, ds, dt);
    float s0 = ss - 0.5 * ds, s1 = ss + 0.5 * ds;
    float t0 = tt - 0.5 * dt, t1 = tt + 0.5 * dt;
    alpha = float texture(texturename[alphachannel], s0, t0, s1, t0, s0, t1, s1, t1,
                          "blur", blur, "fill", 1);
    return color texture(texturename, s0, t0, s1, t0, s0, t1, s1, t1, "blur", blur);
}

float GetFloatTextureAndAlpha (string texturename; string projection; point P;
                               string whichspace; matrix xform; float blur;
                               uniform float alphachannel; output float alpha;)
{
    float ss = 0, tt = 0, ds = 0, dt = 0;
    ProjectTo2D(projection, P, whichspace, xform, ss, tt, ds, dt);
    float s0 = ss - 0.5 * ds, s1 = ss + 0.5 * ds;
    float t0 = tt - 0.5 * dt, t1 = tt + 0.5 * dt;
    alpha = float texture(texturename[alphachannel], s0, t0, s1, t0, s0, t1, s1, t1,
                          "blur", blur, "fill", 1);
    return float texture(texturename, s0, t0, s1, t0, s0, t1, s1, t1, "blur", blur);
}

/* A texture with premultiplied alpha (channel 3) laid over a base value: map + (1-alpha)
 * base. */
color ApplyColorTextureOver (color basecolor; string texturename; string projection;
                             point P; string whichspace; matrix xform; float blur;)
{
    float a = 0;
    color Ct = GetColorTextureAndAlpha(texturename, projection, P, whichspace, xform, blur,
                                       3, a);
    return Ct + (1 - a) * basecolor;
}

float ApplyFloatTextureOver (float baseval; string texturename; string projection;
                             point P; string whichspace; matrix xform; float blur;)
{
    float a = 0;
    float x = GetFloatTextureAndAlpha(texturename, projection, P, whichspace, xform, blur,
                                      3, a);
    return x + (1 - a) * baseval;
}

/* A matrix from 16 floats in RenderMan's row-major order (as a shader parameter array). */
matrix array_to_mx (float m[16])
{
    return matrix(m[0], m[1], m[2], m[3],
                  m[4], m[5], m[6], m[7],
                  m[8], m[9], m[10], m[11],
                  m[12], m[13], m[14], m[15]);
}

#endif /* PROJECT_H */
