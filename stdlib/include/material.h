/* material.h -- arbor's versions of the "Material" functions that Advanced RenderMan
 * (Apodaca & Gritz, 2000, ch. 9) builds its surface shaders from.  Written for arbor from the
 * book's description of each model (not a copy of its file).
 *
 * Each function takes the front-facing shading normal Nf and a base colour and returns the
 * reflected colour (the caller multiplies by opacity).  The viewing direction is -I.
 */
#ifndef MATERIAL_H
#define MATERIAL_H 1

/* Lambertian: ambient plus diffuse. */
color MaterialMatte (normal Nf;  color basecolor;  float Ka, Kd;)
{
    return basecolor * (Ka * ambient() + Kd * diffuse(Nf));
}

/* Plastic: a diffuse base under a white (uncoloured) specular highlight. */
color MaterialPlastic (normal Nf;  color basecolor;  float Ka, Kd, Ks, roughness;)
{
    vector V = -normalize(I);
    return basecolor * (Ka * ambient() + Kd * diffuse(Nf))
         + Ks * specular(Nf, V, roughness);
}

/* Metal with a broad highlight: the highlight takes the metal's colour. */
color MaterialRoughMetal (normal Nf;  color basecolor;  float Ka, Kd, Ks, roughness;)
{
    vector V = -normalize(I);
    return basecolor * (Ka * ambient() + Kd * diffuse(Nf)
                        + Ks * specular(Nf, V, roughness));
}

/* Clay: Oren-Nayar rough diffuse reflection (qualitative model), roughness = sigma in
 * radians; sigma 0 is Lambertian. */
color MaterialClay (normal Nf;  color basecolor;  float Ka, Kd, roughness;)
{
    vector V = -normalize(I);
    float s2 = roughness * roughness;
    float A = 1 - 0.5 * s2 / (s2 + 0.33);
    float B = 0.45 * s2 / (s2 + 0.09);
    float cos_r = V . Nf;
    vector Vp = normalize(V - Nf * cos_r);
    color C = 0;
    illuminance (P, Nf, PI/2) {
        vector Ln = normalize(L);
        float cos_i = Ln . Nf;
        vector Lp = Ln - Nf * cos_i;
        float cos_phi = 0;
        if (length(Lp) > 1e-6)
            cos_phi = max(0, normalize(Lp) . Vp);
        float ti = acos(clamp(cos_i, -1, 1)), tr = acos(clamp(cos_r, -1, 1));
        float alpha = max(ti, tr), beta = min(ti, tr);
        C += Cl * cos_i * (A + B * cos_phi * sin(alpha) * tan(beta));
    }
    return basecolor * (Ka * ambient() + Kd * C);
}

/* Polished plastic or metal reflecting its environment: a mirror term from envname
 * (an environment map, or nothing when empty) scaled by Kr, plus a sharp highlight. */
color MaterialShinyMetal (normal Nf;  color basecolor;  float Ka, Ks, Kr, roughness;
                          string envname;)
{
    vector V = -normalize(I);
    color env = 0;
    if (envname != "") {
        vector R = vtransform("world", reflect(-V, Nf));
        env = color environment(envname, R);
    }
    return basecolor * (Ka * ambient() + Ks * specular(Nf, V, roughness) + Kr * env);
}

#endif /* MATERIAL_H */
