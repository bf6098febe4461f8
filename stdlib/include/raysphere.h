/* raysphere.h -- ray/sphere intersection, with the interface of the header of the same name in
 * Advanced RenderMan (Apodaca & Gritz, 2000): raysphere(E, I, r, eps, t0, t1).  Written for
 * arbor from the book's description, not a copy of its file.
 */
#ifndef RAYSPHERE_H
#define RAYSPHERE_H 1

/* Hits beyond eps of the ray E + t I (I of unit length) with the sphere of radius r about the
 * origin: returns how many (0, 1 or 2) and puts their distances in t0 <= t1.  When only the
 * far hit is beyond eps (E inside the sphere) it is returned in t0.
 *
 * With |I| = 1 the hits solve t^2 + 2(E.I) t + (E.E - r^2) = 0; the book's function solves
 * this form whatever the length of I (shaders that pass an unnormalised direction rely on it),
 * and so does this one.
 */
float raysphere (point E; vector I; float r; float eps; output float t0, t1;)
{
    vector e = vector E;
    float half_b = e . I;
    float c = e . e - r * r;
    float q = half_b * half_b - c;      /* a quarter of the discriminant */
    float n = 0;
    if (q > 0) {
        float root = sqrt(q);
        float near = -half_b - root, far = -half_b + root;
        if (near > eps) {
            t0 = near;
            t1 = far;
            n = 2;
        } else {
            t0 = far;
            n = (far > eps) ? 1 : 0;
        }
    } else if (q == 0) {
        /* grazing: one touching point */
        t0 = -half_b;
        n = (t0 > eps) ? 1 : 0;
    }
    return n;
}

#endif /* RAYSPHERE_H */
