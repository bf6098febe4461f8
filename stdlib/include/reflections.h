/* reflections.h -- reflected light from reflection maps, environment maps of finite radius and
 * ray tracing, with the interface of the header of the same name in Advanced RenderMan
 * (Apodaca & Gritz, 2000, ch. 9): ReflMap, Environment, RayTrace, SampleEnvironment and the
 * ENVPARAMS / DECLARE_ENVPARAMS / DECLARE_DEFAULTED_ENVPARAMS parameter macros.  Written for
 * arbor from the book's description, not a copy of its file.
 *
 * As in the book, rays are traced only when the shader has included rayserver.h (or is
 * compiled with BMRT defined); otherwise SampleEnvironment uses the maps alone.
 */
#ifndef REFLECTIONS_H
#define REFLECTIONS_H 1

#include "filterwidth.h"
#include "raysphere.h"

/* The environment parameters of a shader, as a group: the map's name and the space it was
 * made in ("NDC" for a planar reflection map), the radius of the sphere it stands for, and the
 * jitter and sample count of ray-traced reflections. */
#define ENVPARAMS envname, envspace, envrad, rayjitter, raysamples

#define DECLARE_ENVPARAMS                                   \
        string envname, envspace;                           \
        uniform float envrad, rayjitter, raysamples

#define DECLARE_DEFAULTED_ENVPARAMS                         \
        string envname = "", envspace = "world";            \
        uniform float envrad = 100, rayjitter = 0, raysamples = 1

/* A flat mirror's reflection map: a picture rendered through the mirrored camera, looked up at
 * P's own screen position (NDC, upside down because the mirror flips it).  alpha is the map's
 * fourth channel (1 where it has none).  Takes derivatives. */
color ReflMap (string reflname; point P; float blur; output float alpha;)
{
    point Pndc = transform("NDC", P);
    float x = xcomp(Pndc);
    float y = 1 - ycomp(Pndc);
    alpha = float texture(reflname[3], x, y, "blur", blur, "fill", 1);
    return color texture(reflname, x, y, "blur", blur);
}

/* An environment map taken as a sphere of radius envrad about the origin of envspace, rather
 * than at infinity: the ray (P, R) is followed (in envspace) to where it meets the sphere and
 * the map is looked up in the direction of that point, so nearby objects reflect the
 * environment with parallax.  P outside the sphere is moved onto it first.  alpha is the
 * map's fourth channel (1 where it has none).  Takes derivatives. */
color Environment (string envname, envspace; uniform float envrad;
                   point P; vector R; float blur; output float alpha;)
{
    vector Pe = vector transform(envspace, P);
    vector Re = normalize(vtransform(envspace, R));
    if (Pe . Pe > envrad * envrad)
        Pe = envrad * normalize(Pe);
    vector lookup = Re;
    float t0 = 0, t1 = 0;
    if (raysphere(point Pe, Re, envrad, 1.0e-4, t0, t1) > 0)
        lookup = Pe + t0 * Re;
    alpha = float environment(envname[3], lookup, "blur", blur, "fill", 1);
    return color environment(envname, lookup, "blur", blur);
}

#if (defined(BMRT) || defined(RAYSERVER_H))
#include "arborrays.h"
#endif

/* Ray-traced reflection about the unit direction Rdir from P: the mean of about nsamples
 * stratified rays spread by blur (0 = sharp) with jitter 0..1 (arborrays.h), and in alpha the
 * fraction of them that hit something.  Without ray tracing (rayserver.h not included) it
 * returns black with alpha 0.  Kr below 1e-4 skips the rays.  Takes derivatives. */
color RayTrace (point P; vector Rdir; float Kr, blur, jitter; uniform float nsamples;
                output float alpha;)
{
    color C = 0;
    alpha = 0;
#if (defined(BMRT) || defined(RAYSERVER_H))
    if (Kr >= 1.0e-4)
        C = arbor_raytrace(P, Rdir, blur, jitter, nsamples, alpha);
#endif
    return C;
}

/* Kr times the light arriving at P from direction R: the reflection map (envspace "NDC") or
 * the finite-radius environment map named by envname, under what ray tracing finds (when
 * rayserver.h is included: rays spread by sqrt(blur), composited over the map by their hit
 * fraction). */
color SampleEnvironment (point P; vector R; float Kr, blur; DECLARE_ENVPARAMS;)
{
    color C = 0;
    float alpha = 0;
    if (envname != "") {
        if (envspace == "NDC")
            C = ReflMap(envname, P, blur, alpha);
        else
            C = Environment(envname, envspace, envrad, P, R, blur, alpha);
    }
#if (defined(BMRT) || defined(RAYSERVER_H))
    float hit = 0;
    color Cray = RayTrace(P, R, Kr, sqrt(blur), rayjitter, raysamples, hit);
    C = Cray + (1 - hit) * C;
#endif
    return Kr * C;
}

#endif /* REFLECTIONS_H */
