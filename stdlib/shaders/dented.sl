/* dented: the RenderMan Companion's dent displacement, which Aqsis's and BMRT's shader sets
   carried and scenes name without shipping (Aqsis's vase scene, regression Bug1396028).
   A turbulence of `maxoctaves` octaves, each |0.5 - noise| of shader-space P at doubling
   frequency and halving weight, raised to `power` and pushed inward along N by Km.
   Written for arbor from that documented behaviour; the parameters are BMRT's (Km, power,
   frequency, maxoctaves), whose defaults give the Companion's shader. */
displacement dented(float Km = 1, power = 3, frequency = 1, maxoctaves = 6)
{
    point Pshad = frequency * transform("shader", P);
    float size = 1, magnitude = 0, i;
    for (i = 0; i < maxoctaves; i += 1) {
        magnitude += abs(0.5 - noise(Pshad * size)) / size;
        size *= 2;
    }
    P -= Km * pow(magnitude, power) * normalize(N);
    N = calculatenormal(P);
}
