/* fBm marble: six octaves of noise perturb sine veins; plastic-like lighting.
   The shading-bound benchmark's shader (examples/bench/marble.rib). */
surface fbmmarble(float Ka = 1, Kd = 0.8, Ks = 0.4, roughness = 0.1;
                  float scale = 1, octaves = 6;
                  color veincolor = color(0.15, 0.12, 0.2))
{
    point PP = transform("shader", P) * scale;
    float sum = 0, amp = 1, i;
    point pp = PP;
    for (i = 0; i < octaves; i += 1) {
        sum += amp * (2 * noise(pp) - 1);
        amp *= 0.5;
        pp *= 2.03;
    }
    float v = 0.5 + 0.5 * sin(xcomp(PP) * 4 + sum * 3);
    color Ct = mix(Cs, veincolor, smoothstep(0.2, 0.9, v));
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    Oi = Os;
    Ci = Os * (Ct * (Ka * ambient() + Kd * diffuse(Nf)) + Ks * specular(Nf, V, roughness));
}
