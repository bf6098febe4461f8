/* pshad.h -- shading-space coordinates for solid textures, with the interface of the header of
 * the same name in Advanced RenderMan (Apodaca & Gritz, 2000, ch. 12): PSHAD_PARAMS,
 * DEFAULT_PSHAD_PARAMS and GET_PSHAD.  Written for arbor from the book's description, not a
 * copy of its file.
 *
 *   PSHAD_PARAMS(space, freq)  in a shader's parameter list: declares
 *                              string shadingspace = space; float shadingfreq = freq
 *                              (and varying point Pref when USE_PREF is nonzero);
 *   DEFAULT_PSHAD_PARAMS       PSHAD_PARAMS("shader", 1);
 *   GET_PSHAD                  in the body: declares varying point Pshad, the shading point
 *                              (Pref when the primitive carries one, else P) in shadingspace
 *                              times shadingfreq, and float dPshad, its filter width.
 *
 * Define USE_PREF to 1 before including this header to take reference positions (Pref).
 */
#ifndef PSHAD_H
#define PSHAD_H 1

#include "filterwidth.h"

#ifndef USE_PREF
#define USE_PREF 0
#endif

#if (USE_PREF)

/* A Pref default no primitive will give: it marks "no Pref given". */
#define UNINITIALIZED_PREF point (-1e10, -1e10, -1e10)

#define PSHAD_PARAMS(spacedefault, freqdefault)                             \
        varying point Pref = UNINITIALIZED_PREF;                            \
        string shadingspace = spacedefault;                                 \
        float shadingfreq = freqdefault

#define GET_PSHAD                                                           \
        varying point Pshad = shadingfreq * transform(shadingspace,         \
                 (Pref != UNINITIALIZED_PREF) ? Pref : P);                  \
        float dPshad = filterwidthp(Pshad)

#else

#define PSHAD_PARAMS(spacedefault, freqdefault)                             \
        string shadingspace = spacedefault;                                 \
        float shadingfreq = freqdefault

#define GET_PSHAD                                                           \
        varying point Pshad = shadingfreq * transform(shadingspace, P);     \
        float dPshad = filterwidthp(Pshad)

#endif /* USE_PREF */

#define DEFAULT_PSHAD_PARAMS PSHAD_PARAMS("shader", 1)

#endif /* PSHAD_H */
