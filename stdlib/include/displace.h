/* displace.h -- Displace(), true displacement and bump mapping in one call, with the interface
 * of the header of the same name in Advanced RenderMan (Apodaca & Gritz, 2000, ch. 8).
 * Written for arbor from the book's description, not a copy of its file.
 */
#ifndef DISPLACE_H
#define DISPLACE_H 1

/* Pushes the surface by amp along dir (a unit vector in "current" space), amp being measured
 * in the units of the named space: dir is rescaled by how long a unit current-space step in
 * that direction is in space.  truedisp = 1 moves P (true displacement); truedisp = 0 leaves
 * P and only bends the normal as if it had moved (bump mapping); in between does a share of
 * each.  Returns the unit normal of the pushed surface in "current" space.  When P moves the
 * caller still sets N from the result (N = Displace(...)). */
normal Displace (vector dir; string space; float amp; float truedisp;)
{
    extern point P;
    float units = length(vtransform(space, dir));
    vector offset = dir * (amp / max(units, 1.0e-6));
    P += truedisp * offset;
    return normalize(calculatenormal(P + (1 - truedisp) * offset));
}

#endif /* DISPLACE_H */
