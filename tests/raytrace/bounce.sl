/* Half its own indirect light plus a glow of 0.5: the value seen shows how many diffuse
 * bounces indirectdiffuse() was allowed (0.5, 0.75, 0.875, … for 0, 1, 2, … bounces). */
surface bounce()
{
    normal Nf = faceforward(normalize(N), I);
    Ci = 0.5 * indirectdiffuse(P, Nf, 4) + 0.5;
    Oi = 1;
}
