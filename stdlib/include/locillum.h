/* locillum.h -- local illumination models, with the interface of the header of the same name
 * in Advanced RenderMan (Apodaca & Gritz, 2000, ch. 9): LocIllumOrenNayar,
 * LocIllumWardAnisotropic and LocIllumGlossy.  Written for arbor from the book's description
 * (and the papers it cites), not a copy of its file.
 *
 * Each sums over the lights in the hemisphere of the unit normal N seen from the unit view
 * direction V (towards the eye), scaled like diffuse() and specular(): a white light on a
 * Lambertian surface facing it gives 1, not 1/pi.  Lights with __nondiffuse = 1 are left out
 * of the diffuse model and lights with __nonspecular = 1 out of the specular ones (a fraction
 * scales them).
 *
 * reflectance.h has BRDF-normalised functions of the first two names (1/pi of these); when it
 * was included first its versions are kept, and the other way round.  material.h calls the
 * book-scaled models by their own names (arbor_locillum_*), whatever the order.
 */
#ifndef LOCILLUM_H
#define LOCILLUM_H 1

#ifndef PI
#define PI 3.14159265358979323846
#endif

/* Oren & Nayar's rough diffuse reflection (the qualitative model): roughness is the standard
 * deviation, in radians, of the slopes of the surface's V-grooves; 0 is Lambertian. */
color arbor_locillum_orennayar (normal N; vector V; float roughness;)
{
    extern point P;
    float s2 = roughness * roughness;
    float A = 1 - 0.5 * s2 / (s2 + 0.33);
    float B = 0.45 * s2 / (s2 + 0.09);
    float cos_r = clamp(V . N, -1, 1);
    float theta_r = acos(cos_r);
    vector Vt = V - N * cos_r;             /* V's part across the surface */
    float lvt = length(Vt);
    color C = 0;
    illuminance (P, N, PI / 2) {
        extern vector L;
        extern color Cl;
        float nondiff = 0;
        lightsource("__nondiffuse", nondiff);
        if (nondiff < 1) {
            vector Ln = normalize(L);
            float cos_i = clamp(Ln . N, -1, 1);
            vector Lt = Ln - N * cos_i;
            float llt = length(Lt);
            /* cosine of the azimuth between light and view, only where it is positive */
            float cphi = 0;
            if (lvt > 1.0e-6 && llt > 1.0e-6)
                cphi = max(0, (Lt . Vt) / (llt * lvt));
            float theta_i = acos(cos_i);
            float a = max(theta_i, theta_r), b = min(theta_i, theta_r);
            C += (1 - nondiff) * Cl * cos_i * (A + B * cphi * sin(a) * tan(b));
        }
    }
    return C;
}

/* Ward's anisotropic Gaussian highlight (Ward 1992): xdir is a unit tangent giving the
 * direction of roughness xroughness; across it (N x xdir) the roughness is yroughness.
 * The result is the reflected light sum_lights Cl (N.L) rho, i.e. the paper's BRDF times pi
 * (the scale of specular()). */
color arbor_locillum_ward (normal N; vector V; vector xdir; float xroughness, yroughness;)
{
    extern point P;
    float cos_r = clamp(N . V, 1.0e-4, 1);
    vector X = xdir / xroughness;
    vector Y = (N ^ xdir) / yroughness;
    color C = 0;
    illuminance (P, N, PI / 2) {
        extern vector L;
        extern color Cl;
        float nonspec = 0;
        lightsource("__nonspecular", nonspec);
        if (nonspec < 1) {
            vector Ln = normalize(L);
            float cos_i = Ln . N;
            if (cos_i > 0) {
                vector H = normalize(V + Ln);
                float hx = X . H, hy = Y . H;
                /* the Gaussian in the half-angle, in the form of Ward's paper that needs
                 * no tangent: exp(-2 ((H.x/ax)^2 + (H.y/ay)^2) / (1 + H.N)) */
                float e = exp(-2 * (hx * hx + hy * hy) / (1 + H . N));
                C += (1 - nonspec) * Cl * cos_i * e / sqrt(cos_i * cos_r);
            }
        }
    }
    return C / (4 * xroughness * yroughness);
}

#ifndef ARBOR_REFLECTANCE_H
color LocIllumOrenNayar (normal N; vector V; float roughness;)
{
    return arbor_locillum_orennayar(N, V, roughness);
}

color LocIllumWardAnisotropic (normal N; vector V; vector xdir; float xroughness, yroughness;)
{
    return arbor_locillum_ward(N, V, xdir, xroughness, yroughness);
}
#endif /* ARBOR_REFLECTANCE_H */

/* A highlight with a flat bright core and a sharp edge, for glass, glaze or liquid: the
 * Blinn term (N.H)^(1/roughness) through a smoothstep about 0.72 whose width shrinks from 0.36
 * at sharpness 0 to nothing at sharpness 1. */
color LocIllumGlossy (normal N; vector V; float roughness, sharpness;)
{
    extern point P;
    float w = 0.18 * (1 - sharpness);
    color C = 0;
    illuminance (P, N, PI / 2) {
        extern vector L;
        extern color Cl;
        float nonspec = 0;
        lightsource("__nonspecular", nonspec);
        if (nonspec < 1) {
            vector H = normalize(normalize(L) + V);
            float blinn = pow(max(0, N . H), 1 / roughness);
            C += (1 - nonspec) * Cl * smoothstep(0.72 - w, 0.72 + w, blinn);
        }
    }
    return C;
}

#endif /* LOCILLUM_H */
