/* ======================================================================
 * Advanced-RenderMan style helpers, as they look after preprocessing
 * (filterwidth.h / noises.h / patterns.h macros expanded by hand).
 * ====================================================================== */
float filteredpulse (float edge0, edge1, x, dx)
{
    float x0 = x - dx/2;
    float x1 = x0 + dx;
    return max (0, (clamp(x1,edge0,edge1)-clamp(x0,edge0,edge1))/dx);
}

float fBm (point p; uniform float octaves, lacunarity, gain)
{
    varying float sum = 0, amp = 1;
    varying point pp = p;
    uniform float i;
    for (i = 0;  i < octaves;  i += 1) {
        sum += amp * ((2*noise(pp))-1);
        amp *= gain;  pp *= lacunarity;
    }
    return sum;
}

vector vfBm (point p; float filtwidth; uniform float octaves, lacunarity, gain)
{
    uniform float amp = 1;
    varying point pp = p;
    varying vector sum = 0;
    varying float fw = filtwidth;
    uniform float i;
    for (i = 0;  i < octaves;  i += 1) {
        sum += amp * ((2*(vector noise(pp)))-1) * (1 - smoothstep(0.2, 0.75, fw));
        amp *= gain;  pp *= lacunarity;  fw *= lacunarity;
    }
    return sum;
}

void voronoi_f1f2_3d (point P; float jitter;
                      output float f1; output point pos1;
                      output float f2; output point pos2)
{
    point thiscell = point (floor(xcomp(P))+0.5, floor(ycomp(P))+0.5,
                            floor(zcomp(P))+0.5);
    f1 = f2 = 1000;
    uniform float i, j, k;
    for (i = -1;  i <= 1;  i += 1) {
        for (j = -1;  j <= 1;  j += 1) {
            for (k = -1;  k <= 1;  k += 1) {
                point testcell = thiscell + vector(i,j,k);
                point pos = testcell +
                            jitter * (vector cellnoise (testcell) - 0.5);
                vector offset = pos - P;
                float dist = offset . offset;
                if (dist < f1) {
                    f2 = f1;  pos2 = pos1;
                    f1 = dist;  pos1 = pos;
                } else if (dist < f2) {
                    f2 = dist;  pos2 = pos;
                }
            }
        }
    }
    f1 = sqrt(f1);  f2 = sqrt(f2);
}

color MaterialPlastic (normal Nf;  color basecolor;
                       float Ka, Kd, Ks, roughness;)
{
    extern vector I;
    return basecolor * (Ka*ambient() + Kd*diffuse(Nf))
        + Ks*specular(Nf,-normalize(I),roughness);
}

surface
veinedmarble (float Ka = 1, Kd = 0.8, Ks = 0.4, roughness = 0.075;
              color specularcolor = 1;
              color basecolor = color (.8, .8, .8), veincolor = color(.2, .2, .3);
              float sharpness = 8;
              float veinfreq = 2, veinlevels = 2, warpfreq = 1, warping = 0.5;
              string shadingspace = "shader";
              float shadingfreq = 1;)
{
    point PP = shadingfreq * transform (shadingspace, P);
    float dPP = max(abs(Du(PP)*du) + abs(Dv(PP)*dv), 1.0e-6);
    /* perturb the lookup */
    PP += warping * vfBm (PP*warpfreq, dPP*warpfreq, 6, 2, 0.5);
    float turb = 0, freq = 1;
    uniform float i;
    for (i = 0; i < veinlevels; i += 1) {
        float vein = fBm (PP*freq*veinfreq, 4, 2, 0.5);
        turb += (1 - filteredpulse(-.1, .1, vein, dPP*freq)) / freq;
        freq *= 2;
    }
    turb = pow(smoothstep (0, 1, turb), sharpness);
    color Ct = mix (basecolor, veincolor, turb);
    normal Nf = faceforward (normalize(N), I);
    Ci = MaterialPlastic (Nf, Ct, Ka, Kd, Ks, roughness);
    Oi = Os;  Ci *= Oi;
}
