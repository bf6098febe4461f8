/* normals.h: PRMan's shading-normal helper, as its shipped shaders include it
 * (indirectsurf, cylinderlight, causticlight, indirectlight, ...).
 *
 * shadingnormal(N): N normalized and, for a two-sided primitive or a point reached by a
 * ray, turned to face the viewer (judged by N itself, not Ng: a ray may hit either side).
 * One-sided primitives keep their normal, so their back faces stay dark as PRMan's do.
 * Written for arbor from the documented behaviour; the body is our own.
 */
#ifndef NORMALS_H
#define NORMALS_H

normal shadingnormal(normal Nin)
{
    normal Nunit = normalize(Nin);
    uniform float twosided = 2;
    uniform float depth = 0;
    attribute("Sides", twosided);
    rayinfo("depth", depth);
    normal Nout = Nunit;
    if (twosided != 1 || depth > 0)
        Nout = faceforward(Nunit, I, Nunit);
    return Nout;
}

#endif /* NORMALS_H */
