/* A matte checkerboard in s and t (example shader for the reflection scene), filtered
   with filterstep so it does not alias. */
surface checker(float Ka = 1; float Kd = 1; float freq = 8; color othercolor = color(0.1, 0.1, 0.1);)
{
    normal Nf = faceforward(normalize(N), I);
    float ss = mod(s * freq, 2);
    float tt = mod(t * freq, 2);
    float inside = abs(step(1, ss) - step(1, tt));
    color c = mix(Cs, othercolor, inside);
    Oi = Os;
    Ci = Os * c * (Ka * ambient() + Kd * diffuse(Nf));
}
