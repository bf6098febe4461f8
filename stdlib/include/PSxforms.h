/* PSxforms.h -- feature transforms on texture coordinates, with the interface of the header
 * of the same name in Peter Stuart's PS shaders (RenderMan Repository, 2002; built on Steve
 * May's RManNotes).  Written for arbor from the header's description, not a copy of it.
 *
 * Moving or scaling a feature drawn in (s, t) means applying the inverse to the coordinates:
 * these functions do that, so xform(size, pos, s) draws a feature of the unit square at
 * size `size` moved by `pos`, about the square's centre.
 */
#ifndef PSXFORMS_H
#define PSXFORMS_H 1

#include "rmannotes.sl"

/* The coordinate that makes a feature `size` times larger. */
float xscale (float size, s)
{
    return s / size;
}

/* The coordinate that moves a feature by pos. */
float xtranslate (float pos, s)
{
    return s - pos;
}

/* (s, t) turned by rad radians about the origin. */
void xrotate (float s, t, rad; output float ss, tt)
{
    float c = cos(rad), n = sin(rad);
    ss = c * s - n * t;
    tt = n * s + c * t;
}

/* Scale by size about the centre 0.5, then move by pos. */
float xform (float size, pos, s)
{
    return (s - pos - 0.5) / size + 0.5;
}

/* The same in two dimensions, with a rotation by rad about the centre after the scale. */
void xform (float s_size, t_size, s_pos, t_pos; float rad, s, t; output float ss, tt;)
{
    float a = (s - s_pos - 0.5) / s_size;
    float b = (t - t_pos - 0.5) / t_size;
    xrotate(a, b, rad, ss, tt);
    ss += 0.5;
    tt += 0.5;
}

#endif /* PSXFORMS_H */
