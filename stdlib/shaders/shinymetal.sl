/* RISpec 3.2 Appendix A: shinymetal (the environment lookup is skipped without a map, as
   most renderers do: Appendix A calls it unconditionally) */
surface shinymetal(float Ka = 1; float Ks = 1; float Kr = 1; float roughness = .1;
                   string texturename = "";)
{
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    vector D = reflect(I, Nf);
    color Cr = 0;
    if (texturename != "")
        Cr = Kr * color environment(texturename, vtransform("world", D));
    Oi = Os;
    Ci = Os * Cs * (Ka * ambient() + Ks * specular(Nf, V, roughness) + Cr);
}
