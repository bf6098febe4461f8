/* rtshiny — a polished surface: plastic-like diffuse and highlight plus a ray-traced mirror
 * reflection weighted by Kr (a perfect mirror with Ka = Kd = Ks = 0, Kr = 1). */
surface rtshiny(float Ka = 0.05, Kd = 0.2, Ks = 0.6, roughness = 0.05, Kr = 0.8;
                color specularcolor = 1;)
{
    normal Nf = faceforward(normalize(N), I);
    vector In = normalize(I);
    vector R = reflect(In, Nf);
    Oi = Os;
    Ci = Os * (Cs * (Ka * ambient() + Kd * diffuse(Nf))
               + specularcolor * (Ks * specular(Nf, -In, roughness) + Kr * trace(P, R)));
}
