/* plastic whose normal is perturbed by a bump map (RISpec 3.1 bump(): N += Km · bump(...))
   and whose colour is Cs times a texture map (like paintedplastic), both maps repeated
   `repeat` times over the surface's (s, t). */
surface bumpplastic(string bumpmap = ""; float Km = 0.03; float repeat = 1;
                    string texturename = "";
                    float Ka = 1; float Kd = .5; float Ks = .5; float roughness = .1;
                    color specularcolor = 1;)
{
    normal Nb = N;
    float ss = s * repeat, tt = t * repeat;
    color Ct = Cs;
    if (texturename != "")
        Ct *= color texture(texturename, ss, tt);
    if (bumpmap != "") {
        vector dPds = dPdu / (repeat * Du(s));
        vector dPdt = dPdv / (repeat * Dv(t));
        Nb = N + Km * bump(bumpmap, N, dPds, dPdt, ss, tt);
    }
    normal Nf = faceforward(normalize(Nb), I);
    vector V = -normalize(I);
    Oi = Os;
    Ci = Os * (Ct * (Ka * ambient() + Kd * diffuse(Nf)) +
               specularcolor * Ks * specular(Nf, V, roughness));
}
