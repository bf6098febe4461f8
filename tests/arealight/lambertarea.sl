/* A Lambertian emitter of radiance `intensity` over a surface of area `area`, for area light
 * tests: each sample of the light's surface (P, N) sends Le · A · cos θ' / r², whose mean over
 * samples uniform in area is the irradiance integral. */
light lambertarea(float intensity = 1; float area = 1)
{
    illuminate(P) {
        float r2 = L . L;
        float c = abs(normalize(N) . normalize(L));
        Cl = intensity * area * c / r2;
    }
}
