/* rtglass — a clear dielectric traced both ways: reflection and refraction weighted by the
 * Fresnel terms (fresnel(): Kr + Kt = 1), entering when I runs against N and leaving
 * otherwise; total internal reflection sends everything to the reflection. */
surface rtglass(float Ks = 0.8, roughness = 0.02, eta = 1.5;
                color transmitcolor = color(0.95, 0.98, 0.96);)
{
    normal Nn = normalize(N);
    vector In = normalize(I);
    normal Nf = faceforward(Nn, In);
    float ratio = (In . Nn) < 0 ? 1 / eta : eta;
    float kr, kt;
    vector R, T;
    fresnel(In, Nf, ratio, kr, kt, R, T);
    color crefl = trace(P, R);
    color crefr = 0;
    if (length(T) > 0)
        crefr = trace(P, T);
    else
        kr = 1;
    Oi = 1;
    Ci = kr * crefl + (1 - kr) * transmitcolor * crefr + Ks * specular(Nf, -In, roughness);
}
