/* plastic whose normal is perturbed by a bump map (RISpec 3.1 bump(): N += Km · bump(...)),
   the map repeated `repeat` times over the surface's (s, t). */
surface bumpplastic(string bumpmap = ""; float Km = 0.03; float repeat = 1;
                    float Ka = 1; float Kd = .5; float Ks = .5; float roughness = .1;
                    color specularcolor = 1;)
{
    normal Nb = N;
    if (bumpmap != "") {
        float ss = s * repeat, tt = t * repeat;
        vector dPds = dPdu / (repeat * Du(s));
        vector dPdt = dPdv / (repeat * Dv(t));
        Nb = N + Km * bump(bumpmap, N, dPds, dPdt, ss, tt);
    }
    normal Nf = faceforward(normalize(Nb), I);
    vector V = -normalize(I);
    Oi = Os;
    Ci = Os * (Cs * (Ka * ambient() + Kd * diffuse(Nf)) +
               specularcolor * Ks * specular(Nf, V, roughness));
}
