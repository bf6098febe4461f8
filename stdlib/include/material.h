/* material.h -- arbor's versions of the "Material" functions that Advanced RenderMan
 * (Apodaca & Gritz, 2000, ch. 9) builds its surface shaders from, with the book's interface:
 * MaterialPlastic, MaterialMatte, MaterialRoughMetal, MaterialThinPlastic,
 * MaterialShinyPlastic, MaterialShinyMetal, MaterialClay, MaterialBrushedMetal,
 * MaterialCeramic and MaterialGlass.  Written for arbor from the book's description of each
 * model (not a copy of its file).
 *
 * Each function takes the front-facing unit shading normal Nf and a base colour and returns
 * the reflected colour (the caller multiplies by opacity).  The viewing direction is -I.  The
 * shiny materials take the environment parameters of reflections.h (ENVPARAMS) and trace rays
 * when rayserver.h was included first, as in the book.
 */
#ifndef MATERIAL_H
#define MATERIAL_H 1

#include "locillum.h"
#include "reflections.h"

/* Plastic: a diffuse base under a white (uncoloured) specular highlight. */
color MaterialPlastic (normal Nf;  color basecolor;  float Ka, Kd, Ks, roughness;)
{
    extern vector I;
    vector V = -normalize(I);
    return basecolor * (Ka * ambient() + Kd * diffuse(Nf))
         + Ks * specular(Nf, V, roughness);
}

/* Lambertian: ambient plus diffuse. */
color MaterialMatte (normal Nf;  color basecolor;  float Ka, Kd;)
{
    return basecolor * (Ka * ambient() + Kd * diffuse(Nf));
}

/* Metal with a broad highlight: the highlight takes the metal's colour. */
color MaterialRoughMetal (normal Nf;  color basecolor;  float Ka, Kd, Ks, roughness;)
{
    extern vector I;
    vector V = -normalize(I);
    return basecolor * (Ka * ambient() + Kd * diffuse(Nf)
                        + Ks * specular(Nf, V, roughness));
}

/* Thin plastic (paper, leaves, lampshades): plastic that is also lit through from behind,
 * Kt scaling the diffuse light arriving on the back side. */
color MaterialThinPlastic (normal Nf;  vector V;  color basecolor;
                           float Ka, Kd, Kt, Ks, roughness;)
{
    return basecolor * (Ka * ambient() + Kd * diffuse(Nf) + Kt * diffuse(-Nf))
         + Ks * specular(Nf, V, roughness);
}

/* 1 when the shaded side faces away from the geometric outside (N.I > 0) and the material is
 * one-sided: its reflections are then skipped. */
float arbor_material_backside (uniform float twosided)
{
    extern normal N;
    extern vector I;
    return (twosided == 0 && N . I > 0) ? 1 : 0;
}

/* Plastic with a mirror coat: Fresnel-weighted reflections (index ior) of what
 * SampleEnvironment sees, the diffuse base dimmed by the light the coat reflects. */
color MaterialShinyPlastic (normal Nf;  color basecolor;
                            float Ka, Kd, Ks, roughness, Kr, blur, ior;
                            uniform float twosided;  DECLARE_ENVPARAMS;)
{
    extern point P;
    extern vector I;
    vector In = normalize(I);
    float fr = 0, ft = 0;
    vector R = 0, T = 0;
    fresnel(In, Nf, 1 / ior, fr, ft, R, T);
    ft = 1 - fr;
    if (arbor_material_backside(twosided) != 0)
        fr = 0;
    return ft * basecolor * (Ka * ambient() + Kd * diffuse(Nf))
         + Ks * specular(Nf, -In, roughness)
         + SampleEnvironment(P, R, fr * Kr, blur, ENVPARAMS);
}

/* Polished metal: highlight and mirror reflections both take the metal's colour. */
color MaterialShinyMetal (normal Nf;  color basecolor;
                          float Ka, Kd, Ks, roughness, Kr, blur;
                          uniform float twosided;  DECLARE_ENVPARAMS;)
{
    extern point P;
    extern vector I;
    vector In = normalize(I);
    float kr = Kr;
    if (arbor_material_backside(twosided) != 0)
        kr = 0;
    vector R = reflect(In, Nf);
    return basecolor * (Ka * ambient() + Kd * diffuse(Nf)
                        + Ks * specular(Nf, -In, roughness)
                        + SampleEnvironment(P, R, kr, blur, ENVPARAMS));
}

/* Clay: Oren-Nayar rough diffuse reflection, roughness = sigma in radians (0: Lambertian). */
color MaterialClay (normal Nf;  color basecolor;  float Ka, Kd, roughness;)
{
    extern vector I;
    return basecolor * (Ka * ambient()
                        + Kd * arbor_locillum_orennayar(Nf, -normalize(I), roughness));
}

/* Brushed metal: Ward's anisotropic highlight, rough uroughness along xdir and vroughness
 * across it, in the metal's colour. */
color MaterialBrushedMetal (normal Nf;  color basecolor;  float Ka, Kd, Ks;
                            vector xdir;  float uroughness, vroughness;)
{
    extern vector I;
    color spec = arbor_locillum_ward(Nf, -normalize(I), xdir, uroughness, vroughness);
    return basecolor * (Ka * ambient() + Kd * diffuse(Nf) + Ks * spec);
}

/* Ceramic: plastic with the flat-cored glossy highlight of LocIllumGlossy (its roughness a
 * tenth of the one given, so values comparable with plastic's give similar sizes). */
color MaterialCeramic (normal Nf;  color basecolor;
                       float Ka, Kd, Ks, roughness, specsharpness;)
{
    extern vector I;
    return basecolor * (Ka * ambient() + Kd * diffuse(Nf))
         + Ks * LocIllumGlossy(Nf, -normalize(I), roughness / 10, specsharpness);
}

/* Glass: Fresnel-weighted reflection (Kr, blurred by reflblur) and refraction (Kt, refrblur,
 * index eta, tinted by transmitcolor, sampled with its own ray jitter and count) of what
 * SampleEnvironment sees, a glossy highlight, and a little diffuse colour.  The refracted
 * share is 1 - the reflected one.  Without ray tracing, back faces (N.I > 0) reflect and
 * transmit nothing (their light is what the front face shows); with it, rays below the first
 * level skip reflections. */
color MaterialGlass (normal Nf;  color basecolor;
                     float Ka, Kd, Ks, roughness, Kr, reflblur;
                     float Kt, refrblur, eta;
                     color transmitcolor;
                     uniform float refrrayjitter, refrraysamples;
                     DECLARE_ENVPARAMS;)
{
    extern point P;
    extern vector I;
    extern normal N;
    vector In = normalize(I);
    float kr = 0, kt = 0;
    vector Rl = 0, Rt = 0;
    /* entering (I against N): outside / inside = 1/eta; leaving: eta */
    fresnel(In, Nf, (I . N < 0) ? 1 / eta : eta, kr, kt, Rl, Rt);
    kt = (1 - kr) * Kt;
    kr *= Kr;
#if (defined(BMRT) || defined(RAYSERVER_H))
    if (raylevel() > 0)
        kr = 0;
#else
    if (N . I > 0) {
        kr = 0;
        kt = 0;
    }
#endif
    color Crefl = SampleEnvironment(P, normalize(Rl), kr, reflblur, ENVPARAMS);
    color Crefr = SampleEnvironment(P, normalize(Rt), kt, refrblur,
                                    envname, envspace, envrad,
                                    refrrayjitter, refrraysamples);
    return basecolor * (Ka * ambient() + Kd * diffuse(Nf))
         + Crefl + Ks * LocIllumGlossy(Nf, -In, roughness, 0.5)
         + transmitcolor * Crefr;
}

#endif /* MATERIAL_H */
