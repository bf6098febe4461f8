/* A perfect mirror: the colour seen along the reflected ray, nothing else. */
surface mirrortest()
{
    normal Nf = faceforward(normalize(N), I);
    Ci = trace(P, reflect(normalize(I), Nf));
    Oi = 1;
}
