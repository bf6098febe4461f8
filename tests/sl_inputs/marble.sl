/* Marble with a turbulence loop and user functions (Advanced RenderMan style). */
float turbulence(point Q; uniform float octaves; float lacunarity, gain)
{
    float sum = 0, amp = 1, i;
    point pp = Q;
    for (i = 0;  i < octaves;  i += 1) {
        sum += amp * abs(2 * noise(pp) - 1);
        amp *= gain;
        pp *= lacunarity;
    }
    return sum;
}

color marble_color(float m)
{
    return color spline(
        clamp(2 * m + .75, 0, 1),
        color (0.25, 0.25, 0.35),
        color (0.25, 0.25, 0.35),
        color (0.20, 0.20, 0.30),
        color (0.20, 0.20, 0.30),
        color (0.20, 0.20, 0.30),
        color (0.25, 0.25, 0.35),
        color (0.15, 0.15, 0.26),
        color (0.15, 0.15, 0.26));
}

surface
marble(
    float Ka = 1, Kd = .5, Ks = .5, roughness = .1;
    color specularcolor = 1;
    float veining = 1;
    uniform float octaves = 6;
    string shadingspace = "shader";)
{
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    point PP = transform(shadingspace, P) * veining;
    float marble = turbulence(PP, octaves, 2, 0.5);
    color Ct = marble_color(sin(xcomp(PP) + marble * 3));
    Oi = Os;
    Ci = Os * (Ct * (Ka * ambient() + Kd * diffuse(Nf))
               + specularcolor * Ks * specular(Nf, V, roughness));
}
