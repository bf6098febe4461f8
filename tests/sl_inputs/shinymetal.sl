surface
shinymetal(
    float Ka = 1;
    float Ks = 1;
    float Kr = 1;
    float roughness = .1;
    string texturename = "";)
{
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    vector D = reflect(I, Nf);
    D = vtransform("world", D);
    color env;
    if (texturename != "")
        env = Kr * color environment(texturename, D);
    else
        env = 0;
    Oi = Os;
    Ci = Os * Cs * (Ka*ambient() + Ks*specular(Nf, V, roughness) + env);
}
