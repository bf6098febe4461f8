/* Brick and mortar as a displacement (after the RenderMan Companion's brick pattern):
   mortar grooves are Km deep with smooth shoulders. With truedisp = 0 the surface is not
   moved: only the normal is perturbed (Blinn's bump mapping, N = calculatenormal of the
   displaced point); with truedisp = 1, P moves too. An optional texture adds fine bumps. */
displacement brickbump(float Km = 0.01;
                       float brickwidth = 0.25; float brickheight = 0.08;
                       float mortarthickness = 0.01;
                       float truedisp = 0;
                       string bumpmap = ""; float Kt = 0.3;)
{
    float bmwidth = brickwidth + mortarthickness;
    float bmheight = brickheight + mortarthickness;
    float mwf = mortarthickness * 0.5 / bmwidth;
    float mhf = mortarthickness * 0.5 / bmheight;
    float ss = s / bmwidth;
    float tt = t / bmheight;
    if (mod(tt * 0.5, 1) > 0.5)
        ss += 0.5;
    ss -= floor(ss);
    tt -= floor(tt);
    float groove = smoothstep(0, mwf, ss) * (1 - smoothstep(1 - mwf, 1, ss))
                 * smoothstep(0, mhf, tt) * (1 - smoothstep(1 - mhf, 1, tt));
    float amp = Km * groove;
    if (bumpmap != "")
        amp += Kt * Km * float texture(bumpmap, s, t);
    point Pd = P + amp * normalize(N);
    N = calculatenormal(Pd);
    if (truedisp > 0)
        P = Pd;
}
