/* The surface used when a primitive names none: a facing-ratio shade of Cs, as the
   reference renderers' defaultsurface does. */
surface defaultsurface(float Kd = .8; float Ka = .2;)
{
    float d = abs(normalize(I) . normalize(N));
    Oi = Os;
    Ci = Os * Cs * (Ka + Kd * d);
}
