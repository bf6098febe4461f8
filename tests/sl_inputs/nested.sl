/* Nested functions with output parameters, extern access, loops with break/continue levels. */
surface
nested(
    output varying color Cextra = 0;
    uniform float count = 4;
    float weights[4] = { 1, .5, .25, .125 };
    string mapname = "grid.tx";)
{
    float total = 0;
    void accumulate(float x; output float acc; output color c)
    {
        extern color Cs;
        extern float total;
        acc += x;
        c = Cs * x;
        total++;
    }
    float clampsum(float a, b) { return clamp(a + b, 0, 1); }

    float i, j, acc = 0;
    color c;
    for (i = 0; i < count; i += 1) {
        for (j = 0; j < 4; j++) {
            if (j > i)
                break 1;
            if (weights[j] == 0) continue;
            if (acc > 10) break 2;
            accumulate(weights[j], acc, c);
        }
    }
    while (acc > 1) {
        acc /= 2;
        --acc;
        ++acc;
    }
    float r = texture(mapname[0], s, t, "blur", .1);
    float g = texture("grid.tx"[1], s, t);
    color Ct = color texture(mapname, s, t, "swidth", 2, "twidth", 2);
    float sh = shadow("shadow.map", P, "samples", 16);
    Cextra = Ct * clampsum(r, g) * (1 - sh) + c;
    Ci = acc > 0.5 ? Ct : acc > 0.25 ? c : color "hsv" (0.5, 1, 1);
    ;
}
