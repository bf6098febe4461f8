/*
 * arealight.sl -- the light of an area light source (BMRT's standard `arealight`).
 *
 * Used with AreaLightSource: P and N are a point of the light's surface and its normal, so
 * each point shines into the hemisphere its surface faces, falling off with the square of
 * the distance. The renderer samples the surface (Attribute "light" "nsamples") and averages.
 * The surface is a Lambertian emitter, as BMRT rendered its area lights: what a point
 * receives from a sample is foreshortened by the cosine between the light's normal there and
 * the way to the point (the Cornell box's back wall is dim just under its ceiling light).
 *
 * intensity, lightcolor: as pointlight (on the light's axis).
 */
light arealight(float intensity = 1; color lightcolor = 1)
{
    illuminate(P, N, PI / 2) {
        Cl = intensity * lightcolor * abs(normalize(N) . normalize(L)) / (L . L);
    }
}
