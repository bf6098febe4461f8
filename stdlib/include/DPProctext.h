/* DPProctext.h -- the preprocessor macros of Darwyn Peachey's "proctext.h" (Texturing and
 * Modeling: A Procedural Approach, Ebert et al., ch. 2, "Building Procedural Textures"),
 * under the name the RenderMan Repository's DP shaders include it by.  Written for arbor from
 * the book's text.
 *
 *   snoise(x)        signed noise: noise remapped from [0, 1] to [-1, 1];
 *   PULSE(a, b, x)   1 for a <= x < b, else 0 (the difference of two steps);
 *   boxstep(a, b, x) 0 below a, 1 above b, a straight ramp between.
 *
 * Each is defined only if not defined already (noises.h has its own snoise).
 */
#ifndef DPPROCTEXT_H
#define DPPROCTEXT_H 1

#ifndef snoise
#define snoise(x) (2 * (float noise(x)) - 1)
#endif

#ifndef PULSE
#define PULSE(a, b, x) (step((a), (x)) - step((b), (x)))
#endif

#ifndef boxstep
#define boxstep(a, b, x) clamp(((x) - (a)) / ((b) - (a)), 0, 1)
#endif

#endif /* DPPROCTEXT_H */
