/* rtstripes — matte stripes along s (the book's striped background), antialiased by the
 * stripe's filter width where derivatives exist. */
surface rtstripes(float Ka = 0.2, Kd = 0.8, freq = 8;
                  color stripecolor = color(0.9, 0.15, 0.1);)
{
    normal Nf = faceforward(normalize(N), I);
    float x = mod(s * freq, 1);
    float w = max(abs(Du(s * freq) * du) + abs(Dv(s * freq) * dv), 1e-4);
    float band = filterstep(0.5, x, x + w) ;
    color c = mix(Cs, stripecolor, band);
    Oi = Os;
    Ci = Os * c * (Ka * ambient() + Kd * diffuse(Nf));
}
