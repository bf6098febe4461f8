/* ri.h: the part of the RenderMan Interface C binding that arbor provides to
 * `Procedural "DynamicLoad"` libraries (RISpec 3.2, Appendix C and §5.8).
 *
 * A procedural library exports three functions:
 *
 *     RtPointer ConvertParameters(RtString paramstr);   parse the "parameters" string
 *     RtVoid    Subdivide(RtPointer data, RtFloat detail);  make geometry with the Ri calls
 *     RtVoid    Free(RtPointer data);                    release what ConvertParameters made
 *
 * and is built as a shared object whose Ri symbols stay undefined (the arbor binary defines
 * them):  cc -shared -fPIC -I path/to/arbor/include -o myproc.so myproc.c
 *
 * The `V` forms are arbor's exported functions; the `...` forms (token/value pairs ending with
 * RI_NULL) are inline wrappers in this header that call them. A parameter's number of values
 * comes from its declaration (RiDeclare, or inline: "varying float foo") and the primitive's
 * size, as in any RenderMan C binding. Geometry is generated in the graphics state where the
 * Procedural stands, inside an implicit attribute block.
 */
#ifndef ARBOR_RI_H
#define ARBOR_RI_H

#include <stdarg.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef short RtBoolean;
typedef int RtInt;
typedef float RtFloat;
typedef char *RtToken;
typedef RtFloat RtColor[3];
typedef RtFloat RtPoint[3];
typedef RtFloat RtVector[3];
typedef RtFloat RtNormal[3];
typedef RtFloat RtMatrix[4][4];
typedef RtFloat RtBound[6];
typedef char *RtString;
typedef void *RtPointer;
typedef void RtVoid;
typedef RtVoid (*RtProcSubdivFunc)(RtPointer data, RtFloat detail);
typedef RtVoid (*RtProcFreeFunc)(RtPointer data);
typedef RtVoid (*RtArchiveCallback)(RtToken type, char *format, ...);

#define RI_NULL ((RtToken)0)
#define RI_TRUE 1
#define RI_FALSE 0
#define RI_INFINITY ((RtFloat)1.0e38)
#define RI_EPSILON ((RtFloat)1.0e-10)

/* Standard tokens (plain strings: arbor looks parameters up by name). */
#define RI_P ((RtToken) "P")
#define RI_PZ ((RtToken) "Pz")
#define RI_PW ((RtToken) "Pw")
#define RI_N ((RtToken) "N")
#define RI_NP ((RtToken) "Np")
#define RI_CS ((RtToken) "Cs")
#define RI_OS ((RtToken) "Os")
#define RI_S ((RtToken) "s")
#define RI_T ((RtToken) "t")
#define RI_ST ((RtToken) "st")
#define RI_WIDTH ((RtToken) "width")
#define RI_CONSTANTWIDTH ((RtToken) "constantwidth")
#define RI_KA ((RtToken) "Ka")
#define RI_KD ((RtToken) "Kd")
#define RI_KS ((RtToken) "Ks")
#define RI_KR ((RtToken) "Kr")
#define RI_ROUGHNESS ((RtToken) "roughness")
#define RI_SPECULARCOLOR ((RtToken) "specularcolor")
#define RI_TEXTURENAME ((RtToken) "texturename")
#define RI_INTENSITY ((RtToken) "intensity")
#define RI_LIGHTCOLOR ((RtToken) "lightcolor")
#define RI_FROM ((RtToken) "from")
#define RI_TO ((RtToken) "to")
#define RI_AMPLITUDE ((RtToken) "amplitude")
#define RI_BILINEAR ((RtToken) "bilinear")
#define RI_BICUBIC ((RtToken) "bicubic")

/* ---- the functions arbor exports ---- */

RtVoid RiAttributeBegin(void);
RtVoid RiAttributeEnd(void);
RtVoid RiTransformBegin(void);
RtVoid RiTransformEnd(void);
RtVoid RiIdentity(void);
RtVoid RiTransform(RtMatrix transform);
RtVoid RiConcatTransform(RtMatrix transform);
RtVoid RiTranslate(RtFloat dx, RtFloat dy, RtFloat dz);
RtVoid RiRotate(RtFloat angle, RtFloat dx, RtFloat dy, RtFloat dz);
RtVoid RiScale(RtFloat sx, RtFloat sy, RtFloat sz);
RtVoid RiColor(RtColor color);
RtVoid RiOpacity(RtColor color);
RtToken RiDeclare(char *name, char *declaration);
RtVoid RiShadingRate(RtFloat size);
RtVoid RiSurfaceV(RtToken name, RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiDisplacementV(RtToken name, RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiAtmosphereV(RtToken name, RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiAttributeV(RtToken name, RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiSphereV(RtFloat radius, RtFloat zmin, RtFloat zmax, RtFloat thetamax,
                 RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiConeV(RtFloat height, RtFloat radius, RtFloat thetamax,
               RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiCylinderV(RtFloat radius, RtFloat zmin, RtFloat zmax, RtFloat thetamax,
                   RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiDiskV(RtFloat height, RtFloat radius, RtFloat thetamax,
               RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiTorusV(RtFloat majorradius, RtFloat minorradius, RtFloat phimin, RtFloat phimax,
                RtFloat thetamax, RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiParaboloidV(RtFloat rmax, RtFloat zmin, RtFloat zmax, RtFloat thetamax,
                     RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiHyperboloidV(RtPoint point1, RtPoint point2, RtFloat thetamax,
                      RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiPolygonV(RtInt nvertices, RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiPointsPolygonsV(RtInt npolys, RtInt nverts[], RtInt verts[],
                         RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiPatchV(RtToken type, RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiPointsV(RtInt npoints, RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiReadArchiveV(RtToken name, RtArchiveCallback callback,
                      RtInt n, RtToken tokens[], RtPointer parms[]);
RtVoid RiProcedural(RtPointer data, RtBound bound, RtProcSubdivFunc subdivfunc,
                    RtProcFreeFunc freefunc);
RtVoid RiProcDelayedReadArchive(RtPointer data, RtFloat detail);
RtVoid RiProcRunProgram(RtPointer data, RtFloat detail);
RtVoid RiProcDynamicLoad(RtPointer data, RtFloat detail);
RtVoid RiProcFree(RtPointer data);

/* ---- the `...` forms, as inline wrappers over the V forms ---- */

#define ARBOR_RI_MAXPARAMS 64

/* va_start after a float parameter is what every RenderMan binding does (RISpec declares
 * RiSphere(…, RtFloat thetamax, ...)); it works on every ABI arbor runs on. */
#if defined(__GNUC__) || defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wvarargs"
#endif

/* Collects `token, value, …, RI_NULL` after `last` into arbor_tokens/arbor_parms/arbor_n. */
#define ARBOR_RI_COLLECT(last)                                            \
    RtToken arbor_tokens[ARBOR_RI_MAXPARAMS];                             \
    RtPointer arbor_parms[ARBOR_RI_MAXPARAMS];                            \
    RtInt arbor_n = 0;                                                    \
    {                                                                     \
        va_list arbor_ap;                                                 \
        RtToken arbor_t;                                                  \
        va_start(arbor_ap, last);                                         \
        while ((arbor_t = va_arg(arbor_ap, RtToken)) != RI_NULL &&        \
               arbor_n < ARBOR_RI_MAXPARAMS) {                            \
            arbor_tokens[arbor_n] = arbor_t;                              \
            arbor_parms[arbor_n] = va_arg(arbor_ap, RtPointer);           \
            arbor_n++;                                                    \
        }                                                                 \
        va_end(arbor_ap);                                                 \
    }

static inline RtVoid RiSurface(RtToken name, ...)
{
    ARBOR_RI_COLLECT(name)
    RiSurfaceV(name, arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiDisplacement(RtToken name, ...)
{
    ARBOR_RI_COLLECT(name)
    RiDisplacementV(name, arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiAtmosphere(RtToken name, ...)
{
    ARBOR_RI_COLLECT(name)
    RiAtmosphereV(name, arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiAttribute(RtToken name, ...)
{
    ARBOR_RI_COLLECT(name)
    RiAttributeV(name, arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiSphere(RtFloat radius, RtFloat zmin, RtFloat zmax, RtFloat thetamax, ...)
{
    ARBOR_RI_COLLECT(thetamax)
    RiSphereV(radius, zmin, zmax, thetamax, arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiCone(RtFloat height, RtFloat radius, RtFloat thetamax, ...)
{
    ARBOR_RI_COLLECT(thetamax)
    RiConeV(height, radius, thetamax, arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiCylinder(RtFloat radius, RtFloat zmin, RtFloat zmax, RtFloat thetamax, ...)
{
    ARBOR_RI_COLLECT(thetamax)
    RiCylinderV(radius, zmin, zmax, thetamax, arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiDisk(RtFloat height, RtFloat radius, RtFloat thetamax, ...)
{
    ARBOR_RI_COLLECT(thetamax)
    RiDiskV(height, radius, thetamax, arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiTorus(RtFloat majorradius, RtFloat minorradius, RtFloat phimin,
                             RtFloat phimax, RtFloat thetamax, ...)
{
    ARBOR_RI_COLLECT(thetamax)
    RiTorusV(majorradius, minorradius, phimin, phimax, thetamax,
             arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiParaboloid(RtFloat rmax, RtFloat zmin, RtFloat zmax, RtFloat thetamax, ...)
{
    ARBOR_RI_COLLECT(thetamax)
    RiParaboloidV(rmax, zmin, zmax, thetamax, arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiHyperboloid(RtPoint point1, RtPoint point2, RtFloat thetamax, ...)
{
    ARBOR_RI_COLLECT(thetamax)
    RiHyperboloidV(point1, point2, thetamax, arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiPolygon(RtInt nvertices, ...)
{
    ARBOR_RI_COLLECT(nvertices)
    RiPolygonV(nvertices, arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiPointsPolygons(RtInt npolys, RtInt nverts[], RtInt verts[], ...)
{
    ARBOR_RI_COLLECT(verts)
    RiPointsPolygonsV(npolys, nverts, verts, arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiPatch(RtToken type, ...)
{
    ARBOR_RI_COLLECT(type)
    RiPatchV(type, arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiPoints(RtInt npoints, ...)
{
    ARBOR_RI_COLLECT(npoints)
    RiPointsV(npoints, arbor_n, arbor_tokens, arbor_parms);
}

static inline RtVoid RiReadArchive(RtToken name, RtArchiveCallback callback, ...)
{
    ARBOR_RI_COLLECT(callback)
    RiReadArchiveV(name, callback, arbor_n, arbor_tokens, arbor_parms);
}

#if defined(__GNUC__) || defined(__clang__)
#pragma GCC diagnostic pop
#endif

#ifdef __cplusplus
}
#endif

#endif /* ARBOR_RI_H */
