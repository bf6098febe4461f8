/* Ambient occlusion as the colour. */
surface occltest(float samples = 64)
{
    normal Nf = faceforward(normalize(N), I);
    Ci = occlusion(P, Nf, samples);
    Oi = 1;
}
