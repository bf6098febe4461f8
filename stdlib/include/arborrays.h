/* arborrays.h -- arbor's own ray helpers behind rayserver.h, reflections.h and raytrace.h:
 * BMRT's fulltrace() and areashadow(), and the stratified reflection sampler of Advanced
 * RenderMan's RayTrace(), all built on the shading language's ray built-ins (trace,
 * visibility, rayhittest, raylevel).  Where arbor does not trace rays these built-ins warn
 * once and return their "nothing there" values, so what the helpers compute falls back to
 * "every ray misses": reflections.h then shows the environment map alone.
 */
#ifndef ARBOR_ARBORRAYS_H
#define ARBOR_ARBORRAYS_H 1

/* How far a ray reaches when a segment is needed (scene units). */
#define ARBOR_RAY_FAR 1.0e6

/* BMRT's fulltrace: the colour seen along the ray (pos, dir), the distance to what it hits
 * (1e30 on a miss) with the point and normal hit, and where and in which direction the ray
 * leaves the scene (the ray itself: arbor does not report continued rays).  Returns 1 on a
 * hit.  A hit is what visibility() finds blocking the ray; its distance, point and normal come
 * from rayhittest() where the renderer reports them, else the hit is placed at
 * ARBOR_RAY_FAR (a hit at a distance arbor cannot tell). */
float fulltrace (point pos; vector dir; output color hitcolor; output float hitdist;
                 output point Phit; output normal Nhit; output point Pmiss;
                 output vector Rmiss;)
{
    vector D = normalize(dir);
    hitcolor = color trace(pos, D);
    color open = visibility(pos, pos + ARBOR_RAY_FAR * D);
    float blocked = 1 - (comp(open, 0) + comp(open, 1) + comp(open, 2)) / 3;
    point ph = pos;
    vector nh = -D;
    float d = rayhittest(pos, D, ph, nh);
    float hit = 0;
    hitdist = 1.0e30;
    Phit = pos + ARBOR_RAY_FAR * D;
    Nhit = normal -D;
    if (d < 1.0e10) {
        hit = 1;
        hitdist = d;
        Phit = ph;
        Nhit = normal nh;
    } else if (blocked > 0.5) {
        hit = 1;
        hitdist = ARBOR_RAY_FAR;
    }
    Pmiss = pos;
    Rmiss = D;
    return hit;
}

/* BMRT's areashadow, for light shaders: the fraction of the way from the lit point Ps to the
 * light's position P that is blocked (0 unshadowed, 1 in shadow).  nsamples is accepted for
 * the interface; one segment is tested. */
float areashadow (point Ps; float nsamples)
{
    extern point P;
    color open = visibility(Ps, P);
    return 1 - (comp(open, 0) + comp(open, 1) + comp(open, 2)) / 3;
}

/* The mean colour of an nrays x nrays stratified bundle of rays about Rdir from the
 * micropolygon at P, and in alpha the fraction of them that hit something.  Directions are
 * spread over a square of side blur (in units of the unit direction) across Rdir, origins
 * over 1.5 micropolygons around P; jitter (0..1) moves each sample from its stratum's centre
 * by up to half a stratum.  nrays = ceil(sqrt(nsamples)) for camera-level rays and 1 for
 * secondary rays (the primary rays' bundle already samples them).
 * Takes derivatives of P: call it outside varying conditionals and loops. */
color arbor_raytrace (point P; vector Rdir; float blur, jitter; uniform float nsamples;
                      output float alpha;)
{
    extern float du, dv;
    vector R0 = normalize(Rdir);
    uniform float primary = (raylevel() == 0) ? 1 : 0;
    uniform float nrays = 1;
    if (primary != 0)
        nrays = max(1, ceil(sqrt(nsamples)));
    /* Two unit directions across R0. */
    vector helper = (abs(xcomp(R0)) < 0.6) ? vector(1, 0, 0) : vector(0, 1, 0);
    vector across1 = normalize(R0 ^ helper);
    vector across2 = R0 ^ across1;
    /* The micropolygon, a little enlarged so neighbouring bundles overlap. */
    vector Eu = Du(P) * (1.5 * du);
    vector Ev = Dv(P) * (1.5 * dv);
    float amount = jitter * primary;
    color sum = 0;
    float hits = 0;
    uniform float i, j;
    for (i = 0; i < nrays; i += 1) {
        for (j = 0; j < nrays; j += 1) {
            float a = (i + 0.5 + amount * (float random() - 0.5)) / nrays - 0.5;
            float b = (j + 0.5 + amount * (float random() - 0.5)) / nrays - 0.5;
            float c = (j + 0.5 + amount * (float random() - 0.5)) / nrays - 0.5;
            float e = (i + 0.5 + amount * (float random() - 0.5)) / nrays - 0.5;
            vector R = normalize(R0 + blur * (a * across1 + b * across2));
            point Pr = P + c * Eu + e * Ev;
            color Ct = 0;
            float dist = 1.0e30;
            point ph = Pr, pm = Pr;
            normal nh = 0;
            vector rm = R;
            fulltrace(Pr, R, Ct, dist, ph, nh, pm, rm);
            sum += Ct;
            hits += (dist < 1.0e10) ? 1 : 0;
        }
    }
    uniform float total = nrays * nrays;
    alpha = hits / total;
    return sum / total;
}

#endif /* ARBOR_ARBORRAYS_H */
