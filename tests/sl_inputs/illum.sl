/* A hand-written diffuse+Phong loop with illuminance. */
surface
myplastic(
    float Ka = 1, Kd = .5, Ks = .5, roughness = .1;
    color specularcolor = 1;
    string lightcategory = "";)
{
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    color Cdiff = 0, Cspec = 0;
    illuminance(P, Nf, PI/2) {
        vector Ln = normalize(L);
        Cdiff += Cl * (Nf . Ln);
        vector H = normalize(Ln + V);
        Cspec += Cl * pow(max(0, Nf . H), 1/roughness);
    }
    illuminance(lightcategory, P, Nf, PI/2)
        Ci += Cl * (N . normalize(L));
    Oi = Os;
    Ci = Os * (Cs * (Ka * ambient() + Kd * Cdiff) + specularcolor * Ks * Cspec);
}
