/* planet — an Earth-like planet for a sphere: continents where band-limited fBm on the unit
 * sphere rises above `sealevel` (oceans below, deeper blue further down), land coloured by
 * latitude and elevation (green lowlands, dry uplands, ice caps at the poles), a cloud layer
 * of turbulence drawn over it and a soft atmosphere at the limb.  Evaluated on the
 * shading-space point projected to the unit sphere, so it is fixed to the planet. */
#include "noises.h"

surface planet(float Ka = 1; float Kd = 1; float Ks = 0.5; float roughness = 0.15;
               float sealevel = 0.05; float icelatitude = 0.86; float cloudcover = 0.5;
               float landfreq = 1.6; float seed = 0;
               color ocean = color(0.02, 0.10, 0.32);
               color shallows = color(0.05, 0.28, 0.48);
               color lowland = color(0.20, 0.38, 0.12);
               color upland = color(0.52, 0.44, 0.30);
               color ice = color(0.92, 0.94, 0.98);
               color atmosphere = color(0.4, 0.6, 1.0);
               string shadingspace = "shader";)
{
    point PP = transform(shadingspace, P);
    point S = point(0, 0, 0) + normalize(PP - point(0, 0, 0));
    point Q = S * landfreq + vector(seed * 13.7, seed * 7.1, seed * 3.3);
    float fw = filterwidthp(Q);
    float e = fBm(Q, fw, 8, 2, 0.5);
    float lat = abs(zcomp(S));
    float de = filterwidth(e);
    float land = filteredsmoothstep(sealevel - 0.01, sealevel + 0.01, e, de);
    color sea = mix(ocean, shallows, smoothstep(sealevel - 0.25, sealevel, e));
    color ground = mix(lowland, upland, smoothstep(sealevel + 0.05, sealevel + 0.4, e));
    color C = mix(sea, ground, land);
    /* ice caps, ragged by the elevation noise */
    float icy = smoothstep(icelatitude - 0.04, icelatitude + 0.04, lat + 0.15 * e);
    C = mix(C, ice, icy);
    /* clouds */
    point Qc = S * 3 + vector(5.2, 1.3, 9.1);
    float fwc = filterwidthp(Qc);
    vector warp = vfBm(Qc, fwc, 3, 2, 0.5);
    float cl = turbulence(Qc + 0.6 * warp, fwc, 6, 2, 0.5);
    float cloud = smoothstep(1 - cloudcover, 1.05 - cloudcover + 0.35, cl + 0.15);
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    float wet = (1 - land) * (1 - icy) * (1 - cloud);
    color surf = C * (Ka * ambient() + Kd * diffuse(Nf)) + wet * Ks * specular(Nf, V, roughness);
    surf = mix(surf, (Ka * ambient() + Kd * diffuse(Nf)), cloud);
    /* atmospheric limb */
    float limb = pow(1 - abs(Nf . V), 3);
    Oi = Os;
    Ci = Os * (surf + limb * atmosphere * 0.6 * (Ka * ambient() + diffuse(Nf)));
}
