/* Constructors with spaces, matrices, arrays, casts, gather, message passing. */
light
arealight(float intensity = 1; color lightcolor = 1;
          point from = point "world" (0, 0, 0);
          vector dir = vector "object" (0, 0, 1);
          matrix xf = matrix "shader" 1;
          matrix m16 = (1, 0, 0, 0,  0, 1, 0, 0,  0, 0, 1, 0,  0, 0, 0, 1);)
{
    normal n = normal "world" (0, 1, 0);
    uniform float a[3] = {1, 2, 3}, b[2];
    float x = float 1;
    vector v = vector "object" dir;
    point p = transform("camera", "world", from);
    float dd = float float a[1];
    illuminate(from, dir, PI / 4) {
        Cl = intensity * lightcolor * (1 - smoothstep(0, 1, length(L)));
    }
    solar() { Cl = 0; }
    solar(dir, 0.1) Cl += 1;
}

surface
gatherer(float samples = 16; float Kd = 1;)
{
    color hitc = 0, sum = 0;
    float count = 0;
    gather("illuminance", P, N, PI/2, samples, "surface:Ci", hitc) {
        sum += hitc;
        count += 1;
    } else {
        sum += color environment("sky.env", N);
    }
    gather("illuminance", P, N, PI/2, samples) ;
    float kd = 1;
    if (surface("Kd", kd) != 0 && displacement("amp", kd) == 0 || !(kd >= 1))
        kd = -kd;
    Ci = sum / max(count, 1) * kd + (1.5e-3 + 2.f + 1e2);
    printf("done %f %s\n", count, "tab\there \"quoted\"");
}

imager nothing() { }

displacement dented(float Km = 1;) {
    float magnitude = 0, size = 1, i;
    point P2 = transform("shader", P);
    for (i = 0; i < 6.0; i += 1) {
        magnitude += abs(.5 - noise(P2 * size)) / size;
        size *= 2;
    }
    P = P - N * (magnitude * magnitude * magnitude) * Km;
    N = calculatenormal(P);
}

transformation twist(float angle = 0;) { P = rotate(P, angle * zcomp(P), point (0,0,0), point (0,0,1)); }
