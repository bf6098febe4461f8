/* A window: the colour seen straight through, along the incident ray. */
surface passthrough()
{
    Ci = trace(P, normalize(I));
    Oi = 1;
}
