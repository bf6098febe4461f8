/* horizonbump: bump mapping with Max's horizon-mapped bump shadows (notes shading.md §4).
 *
 * horizonmap: a table built by `arbor horizon height.png table.hzn`; its stored heights drive
 * the bump (Max's scaling: displacement = bumpscale * F * |dP/ds x dP/dt|^(1/2)), its horizon
 * angles the shadows the bumps cast on the surface. The map tiles (s*repeats, t*trepeats).
 * The bumps stand on the side of the surface facing the eye. shadows = 0 gives plain (Blinn) bump mapping for comparison. In shadow a light keeps
 * shadowambient of its diffuse contribution (Max's 7% "earthshine"), so the bumps still read.
 * penumbra is the light's angular diameter in degrees (soft shadow edges). curvature weights
 * Max's correction for curved surfaces (1: raised points see past the smooth terminator by
 * sqrt(2h/R); 0: flat tables only).
 */
surface horizonbump(float Ka = 1, Kd = 0.8, Ks = 0.2, roughness = 0.15;
                    color specularcolor = 1;
                    string horizonmap = "";
                    float bumpscale = 0.05, srepeats = 1, trepeats = 1;
                    float shadows = 1, penumbra = 1, shadowambient = 0.07;
                    float curvature = 1;)
{
    float ss = s * srepeats, tt = t * trepeats;
    /* Bumps stand on the side facing the eye (the horizon built-in assumes the same). */
    normal Nn = faceforward(normalize(N), I);
    point Pb = P;
    if (horizonmap != "")
        Pb = P + Nn * horizonheight(horizonmap, ss, tt, "scale", bumpscale);
    normal Nb = normalize(calculatenormal(Pb));
    if (Nb . Nn < 0)
        Nb = -Nb;
    normal Nf = faceforward(Nb, I);
    vector V = -normalize(I);
    color C = 0;
    illuminance(P, Nf, PI / 2) {
        vector Ln = normalize(L);
        float vis = 1;
        if (shadows != 0 && horizonmap != "")
            vis = horizon(horizonmap, ss, tt, L, "scale", bumpscale, "penumbra", penumbra,
                          "curvature", curvature);
        float k = mix(shadowambient, 1, vis);
        C += Cl * (k * Kd * Cs * (Nf . Ln)
                   + vis * Ks * specularcolor * specularbrdf(Ln, Nf, V, roughness));
    }
    Oi = Os;
    Ci = Os * (Ka * Cs * ambient() + C);
}
