/* rclocillum.h -- the illumination helpers of Rudy Cortes' shaders (The RenderMan Shading
 * Language Guide, Cortes & Raghavachary, 2007; the RenderMan Repository's RudyC shaders):
 * wrappedDiffuse() (Rob Bredow's wrapped lighting, SIGGRAPH 2002 course 16) and glossy()
 * (Matt Pharr's glossy highlight, same course), with their interface.  Written for arbor from
 * the published description, not a copy of the file.
 *
 * Both sum over the lights (the repository's copy kept only the last light's contribution).
 */
#ifndef RCILLUM_H
#define RCILLUM_H 1

#ifndef PI
#define PI 3.14159265358979323846
#endif

/* Diffuse light that falls off linearly with the angle between the normal and the light,
 * reaching 0 at wrappedAngle (radians) instead of following the cosine: PI/2 gives a soft
 * terminator, larger angles light more of the shadow side.  Lights behind the surface's
 * hemisphere are not counted. */
color wrappedDiffuse (normal n; float wrappedAngle;)
{
    extern point P;
    normal Nn = normalize(n);
    color C = 0;
    illuminance (P, Nn, PI / 2) {
        extern vector L;
        extern color Cl;
        float angle = acos(clamp(normalize(L) . Nn, -1, 1));
        C += Cl * max(0, 1 - angle / wrappedAngle);
    }
    return C;
}

/* A highlight with a flat bright core and a sharp edge (Pharr): the Blinn term
 * (N.H)^(1/roughness) through a smoothstep about 0.72 of half-width 0.18 (1 - sharpness),
 * times Ks and specularcolor.  V is the incident direction (normalize(I), towards the
 * surface), as these shaders pass it.  Lights with __nonspecular are scaled by 1 - it. */
color glossy (normal Nf; vector V; float roughness, sharpness, Ks; color specularcolor;)
{
    extern point P;
    float w = 0.18 * (1 - sharpness);
    color C = 0;
    illuminance (P, Nf, PI / 2) {
        extern vector L;
        extern color Cl;
        float nonspec = 0;
        lightsource("__nonspecular", nonspec);
        vector H = normalize(normalize(L) - V);
        float blinn = pow(max(H . Nf, 0), 1 / roughness);
        C += Cl * specularcolor * Ks * smoothstep(0.72 - w, 0.72 + w, blinn) * (1 - nonspec);
    }
    return C;
}

#endif /* RCILLUM_H */
