/* The irradiance at P from every light, on the side of the surface facing away from the
 * camera (the lights of the area light tests are behind the receiver). */
surface irradiance()
{
    normal Nl = normalize(N);
    if (Nl . I < 0)
        Nl = -Nl;
    Ci = 0;
    illuminance(P, Nl, PI / 2) {
        Ci += Cl * (normalize(L) . Nl);
    }
    Oi = 1;
}
