/* rayserver.h -- the interface of Larry Gritz's "ray server" header (Advanced RenderMan:
 * Beyond the Companion, SIGGRAPH '98 course 11; used throughout Advanced RenderMan, Apodaca &
 * Gritz 2000), written for arbor.
 *
 * The original turned trace(), visibility(), rayhittest(), fulltrace() and areashadow() into
 * calls of a PRMan plug-in that asked BMRT to trace the rays.  arbor has these as built-ins
 * (trace, visibility, rayhittest, raylevel, isshadowray) or defines them on top of the
 * built-ins (fulltrace, areashadow: arborrays.h), so this header only provides the names
 * shaders expect: RAYSERVER_H itself (reflections.h, material.h and uberlight test it to
 * switch on ray-traced reflections and shadows) and the world-space helpers worldp/worldv.
 */
#ifndef RAYSERVER_H
#define RAYSERVER_H 1

#ifndef BMRT
#define worldp(p) transform("world", p)
#define worldv(v) vtransform("world", v)
#endif

#include "arborrays.h"

/* The ray server's radiosity lookup (K-3D's `indirect` light asks it for the indirect light
 * arriving at Ps about Ns): arbor's traced indirect diffuse light there. */
#ifndef rs_indirect
#define rs_indirect(Ps, Ns) indirectdiffuse(Ps, normalize(Ns), 64)
#endif

#endif /* RAYSERVER_H */
