/*
 * arealight.sl -- the light of an area light source (BMRT's standard `arealight`).
 *
 * Used with AreaLightSource: P and N are a point of the light's surface and its normal, so
 * each point shines into the hemisphere its surface faces, falling off with the square of
 * the distance. The renderer samples the surface (Attribute "light" "nsamples") and averages.
 *
 * intensity, lightcolor: as pointlight.
 */
light arealight(float intensity = 1; color lightcolor = 1)
{
    illuminate(P, N, PI / 2) {
        Cl = intensity * lightcolor / (L . L);
    }
}
