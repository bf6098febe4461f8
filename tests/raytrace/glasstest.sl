/* Pure refraction (no reflection): entering when I runs against N, leaving otherwise. */
surface glasstest(float ior = 1.5)
{
    normal Nn = normalize(N);
    vector In = normalize(I);
    float eta = 1 / ior;
    normal Nf = Nn;
    if (Nn . In > 0) {
        Nf = -Nn;
        eta = ior;
    }
    Ci = trace(P, refract(In, Nf, eta));
    Oi = 1;
}
