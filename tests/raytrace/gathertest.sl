/* gather over the hemisphere: the mean hit colour, and the mean hit distance in alpha-free red. */
surface gathertest(float samples = 16)
{
    normal Nf = faceforward(normalize(N), I);
    color sum = 0, hitc = 0;
    float hits = 0, len = 0;
    gather("illuminance", P, Nf, PI / 2, samples, "surface:Ci", hitc, "ray:length", len) {
        sum += hitc;
        hits += 1;
    } else {
        sum += color(0, 0, 0);
    }
    Ci = sum / samples;
    Oi = 1;
}
