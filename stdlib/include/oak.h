/* oak.h -- oaktexture(), the ring-and-grain wood pattern of Advanced RenderMan (Apodaca &
 * Gritz, 2000, ch. 12: the "oak" and "oakplank" shaders), with the book's interface.  Written
 * for arbor from the book's description of the pattern, not a copy of its file.
 */
#ifndef OAK_H
#define OAK_H 1

#include "noises.h"
#include "patterns.h"

/* One octave of the fine grain: pores are the low values of noise over a domain stretched
 * 20 times along the trunk, weighted towards the dark part of the rings; the octave fades
 * out as the footprint fw (in octave cycles) reaches 0.6.  Returns its darkening (0..grainy)
 * and in visible how much of it shows. */
float arbor_oak_grain (point Pg; float fw, inring, grainy; output float visible;)
{
    visible = 1 - smoothstep(0.2, 0.6, fw);
    float dark = 0;
    if (visible > 0) {
        float n = visible * snoise(Pg) * mix(0.3, 1, inring);
        float pore = clamp(0.8 - n, 0, 1);
        dark = grainy * smoothstep(0.5, 1, pore * pore);
    }
    return dark;
}

/* The oak pattern at Pshad (filter width dPshad): 0 in the light wood between rings, 1 in the
 * darkest ring or pore.  Rings are cylinders about the z axis of Pshad's space, spaced
 * 1/ringfreq, their widths varied by ringunevenness; the domain is warped by fBm
 * (ringnoise, ringnoisefreq), the trunk's axis wanders in x and y along z (trunkwobble,
 * trunkwobblefreq), and rings ripple around the axis (angularwobble, angularwobblefreq).
 * Fine grain of frequency grainfreq runs along z.  ringy and grainy scale the rings and the
 * grain (0 turns them off).  Takes derivatives: call it outside varying conditionals. */
float oaktexture (point Pshad; float dPshad;
                  float ringfreq, ringunevenness, grainfreq;
                  float ringnoise, ringnoisefreq;
                  float trunkwobble, trunkwobblefreq;
                  float angularwobble, angularwobblefreq;
                  float ringy, grainy;)
{
    extern float du, dv;
    /* Warp the whole domain a little, then let the axis wander along z. */
    point Pr = Pshad + ringnoise * vfBm(Pshad * ringnoisefreq, dPshad * ringnoisefreq,
                                        2, 4, 0.5);
    Pr += trunkwobble * vsnoise(zcomp(Pshad) * trunkwobblefreq) * vector(1, 1, 0);

    /* Ring number: distance from the axis in ring spacings, rippled around the axis (not
     * near the pith) and made uneven by noise of the ring number itself. */
    float rings = ringfreq * sqrt(xcomp(Pr) * xcomp(Pr) + ycomp(Pr) * ycomp(Pr));
    rings += angularwobble * smoothstep(0, 5, rings)
           * snoise(angularwobblefreq * Pr * vector(1, 1, 0.1));
    float wr = filterwidth(rings);
    rings += ringunevenness * filteredsnoise(rings, wr);

    /* Ring profile over one period: rises over 0.1-0.55, falls over 0.7-0.95. */
    float inring = smoothpulsetrain(0.1, 0.55, 0.7, 0.95, 1, rings);

    /* Two octaves of grain; the first also lightens the rings where it shows. */
    point Pg = Pshad * grainfreq * vector(1, 1, 0.05);
    float fg = filterwidthp(Pg);
    float shown = 0;
    float g1 = arbor_oak_grain(Pg, fg, inring, grainy, shown);
    inring *= 1 - 0.4 * shown;
    float g2 = arbor_oak_grain(2 * Pg, 2 * fg, inring, grainy, shown);
    float grain = max(g1, g2);

    return mix(inring * ringy, 1, grain);
}

#endif /* OAK_H */
