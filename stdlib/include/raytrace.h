/* raytrace.h -- the RayTrace() helper of Larry Gritz's ray-server notes (Advanced RenderMan:
 * Beyond the Companion, SIGGRAPH '98 course 11), the five-argument form shaders of that time
 * call as RayTrace(P, Rdir, blur, jitter, nsamples), written for arbor on its ray built-ins.
 * (reflections.h has the later seven-argument form with Kr and alpha; both may be included.)
 */
#ifndef RAYTRACE_H
#define RAYTRACE_H 1

#include "arborrays.h"

/* The mean colour seen by a jittered, stratified bundle of about nsamples rays around the
 * unit direction Rdir from the micropolygon at P (blur: the bundle's spread; jitter 0..1).
 * Takes derivatives: call it outside varying conditionals and loops. */
color RayTrace (point P; vector Rdir; float blur, jitter; uniform float nsamples;)
{
    float alpha = 0;
    return arbor_raytrace(P, Rdir, blur, jitter, nsamples, alpha);
}

#endif /* RAYTRACE_H */
