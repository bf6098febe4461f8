/* maps.h: PRMan's decal-mapping functions, as its shipped shaders include them (texmap,
 * diaknurl, sinknurl, threads): projections of a point to map coordinates (uu, vv) and
 * decalmap, which picks one and bilinearly maps the result through four (s, t) corners.
 *
 *   bilerp(uu, vv, x1, x2, x3, x4)   x1..x4 at (0,0) (1,0) (0,1) (1,1)
 *   planemap(p, uu, vv, origin, xaxis, yaxis)
 *       uu, vv: distances of p - origin along the unit directions to xaxis and yaxis
 *   cylinmap(p, uu, vv, origin, xaxis, yaxis, zaxis)
 *       uu: angle about the axis origin -> zaxis from the xaxis direction, in [0, 1)
 *       vv: distance of p - origin along that axis (not normalized)
 *   sphermap(p, uu, vv, origin, xaxis, yaxis, zaxis)
 *       uu: longitude in [0, 1) from xaxis; vv: 0 at the south pole (-zaxis) to 1 at zaxis
 *   automap(p, uu, vv, origin, yaxis, n)
 *       a planar map in the plane across n, with yaxis as "up" (another axis when up is
 *       along n), so each facet of a polygon mesh gets its own planar projection
 *   decalmap(p, s, t, ss, tt, maptype, origin, xaxis, yaxis, zaxis, s1,t1 .. s4,t4, n)
 *       maptype 0 planar, 1 cylindrical, 2 spherical, 3 the surface's own (s, t),
 *       4 automap; returns 0
 *
 * The axes are points (their directions from the origin count); callers put every point in
 * one space first (PRMan's shaders use "shader" space). Written for arbor from the
 * documented interface; the bodies are our own.
 */
#ifndef MAPS_H
#define MAPS_H

float bilerp(float uu, vv, x1, x2, x3, x4)
{
    float bottom = mix(x1, x2, uu);
    float top = mix(x3, x4, uu);
    return mix(bottom, top, vv);
}

/* Longitude of direction d about the frame (ex, ey) as a fraction of a turn in [0, 1). */
float maps_turn(vector d, ex, ey)
{
    float f = atan(d . ey, d . ex) / (2 * PI);
    return (f < 0) ? f + 1 : f;
}

void planemap(point p; output float uu, vv; point maporigin, xaxis, yaxis)
{
    vector d = p - maporigin;
    uu = d . normalize(xaxis - maporigin);
    vv = d . normalize(yaxis - maporigin);
}

void cylinmap(point p; output float uu, vv; point maporigin, xaxis, yaxis, zaxis)
{
    vector d = p - maporigin;
    uu = maps_turn(normalize(d), normalize(xaxis - maporigin),
                   normalize(yaxis - maporigin));
    vv = d . normalize(zaxis - maporigin);
}

void sphermap(point p; output float uu, vv; point maporigin, xaxis, yaxis, zaxis)
{
    vector d = normalize(p - maporigin);
    uu = maps_turn(d, normalize(xaxis - maporigin), normalize(yaxis - maporigin));
    float up = clamp(d . normalize(zaxis - maporigin), -1, 1);
    vv = 1 - acos(up) / PI;
}

void automap(point p; output float uu, vv; point maporigin, yaxis; normal n)
{
    vector across = normalize(vector n);
    vector up = normalize(yaxis - maporigin);
    if (abs(across . up) > 0.99) {
        /* "up" lies along the normal: take the frame's y axis, or z if that does too */
        up = (abs(across . vector(0, 1, 0)) > 0.99) ? vector(0, 0, 1) : vector(0, 1, 0);
    }
    vector side = up ^ across;
    up = across ^ side;
    vector d = p - maporigin;
    uu = d . side;
    vv = d . up;
}

float decalmap(point p; float s, t; output float ss, tt; float maptype;
               point maporigin, xaxis, yaxis, zaxis;
               float s1, t1, s2, t2, s3, t3, s4, t4; varying normal n)
{
    float uu = 0, vv = 0;
    if (maptype == 3) {
        ss = s;
        tt = t;
    } else {
        if (maptype == 0)
            planemap(p, uu, vv, maporigin, xaxis, yaxis);
        else if (maptype == 1)
            cylinmap(p, uu, vv, maporigin, xaxis, yaxis, zaxis);
        else if (maptype == 2)
            sphermap(p, uu, vv, maporigin, xaxis, yaxis, zaxis);
        else if (maptype == 4)
            automap(p, uu, vv, maporigin, yaxis, n);
        ss = bilerp(uu, vv, s1, s2, s3, s4);
        tt = bilerp(uu, vv, t1, t2, t3, t4);
    }
    return 0;
}

#endif /* MAPS_H */
