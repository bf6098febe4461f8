/* Aqsis's map form of occlusion(): the map (never made here) names a set of shadow maps
 * rendered around the scene; arbor traces the hemisphere instead. Samples 0 with a
 * "samples" parameter, and a "blur", as Aqsis's envlight example passes them. */
surface occlmaptest(string mapname = "occlmap.sm")
{
    normal Nf = faceforward(normalize(N), I);
    Ci = occlusion(mapname, P, Nf, 0, "blur", 0.025, "samples", 16);
    Oi = 1;
}
