/* texturetree — a texture tree (book §14.1, notes/shading.md §5.4) written in SL:
 *
 *                    root: mask = polka dots (scaled locally by dotfreq)
 *                   /                                           \
 *      left: node, mask = stripes                      right: leaf "gold"
 *      (uvscale stripefreq, local)                     (Cook–Torrance metal,
 *       /                  \                            shaded at the leaf)
 *  leaf "wood"          leaf "painted"
 *  (rings, matte)       (plastic, high Ks)
 *
 * Node semantics (with E9 fixed): col = left + m·(right − left) per channel, m clamped to
 * [0,1]; when m ≤ 0 the right branch is not evaluated at all, when m ≥ 1 the left is not
 * (the short-circuit, done here with varying `if`s).  Shading happens at the leaves (the
 * cola-bottle case: each leaf has its own specular), and a node's coordinate scaling is local
 * to that node: its children see the original (s, t).  Masks are box filtered over the
 * footprint, so the mix is the anti-aliasing too. */
#include "noises.h"
#include "patterns.h"
#include "reflectance.h"

surface texturetree(float Ka = 1; float Kd = 0.8;
                    float dotfreq = 6; float dotradius = 0.3;
                    float stripefreq = 10; float stripewidth = 0.5;
                    color paint = color(0.1, 0.25, 0.7);
                    color wood1 = color(0.75, 0.5, 0.27);
                    color wood2 = color(0.45, 0.24, 0.1);)
{
    normal Nf = faceforward(normalize(N), I);
    vector V = -normalize(I);
    color amb = Ka * ambient();
    color dif = Kd * diffuse(Nf);

    /* root mask: filtered polka dots in locally scaled (s, t) */
    float ss = s * dotfreq;
    float tt = t * dotfreq;
    float ds = filterwidth(ss);
    float dt = filterwidth(tt);
    float cs = ss - floor(ss) - 0.5;
    float ct = tt - floor(tt) - 0.5;
    float d = sqrt(cs * cs + ct * ct);
    float mroot = 1 - filteredsmoothstep(dotradius - 0.02, dotradius + 0.02, d, max(ds, dt));
    /* a footprint wider than a dot cell: the dots' area fraction */
    mroot = mix(mroot, PI * dotradius * dotradius, smoothstep(0.3, 0.7, max(ds, dt)));
    mroot = clamp(mroot, 0, 1);

    color Cleft = 0;
    color Cright = 0;
    if (mroot < 1) {
        /* left node: stripes mask in its own local scale */
        float su = s * stripefreq;
        float mstripe = filteredpulsetrain(stripewidth, 1, su, filterwidth(su));
        color Cwood = 0;
        color Cpaint = 0;
        if (mstripe < 1) {
            /* leaf: wood rings (matte), from the original (s, t) */
            point W = point(s * 4 - 2, t * 0.5, t * 4 - 2);
            float r = sqrt(xcomp(W) * xcomp(W) + zcomp(W) * zcomp(W)) * 6;
            float late = filteredpulsetrain(0.7, 1, r, filterwidth(r));
            Cwood = mix(wood1, wood2, late) * (amb + dif);
        }
        if (mstripe > 0) {
            /* leaf: glossy paint */
            Cpaint = paint * (amb + dif) + 0.6 * specular(Nf, V, 0.08);
        }
        Cleft = mix(Cwood, Cpaint, mstripe);
    }
    if (mroot > 0) {
        /* leaf: polished gold, Cook–Torrance, plus a fake environment */
        vector R = vtransform("world", reflect(I, Nf));
        color env = fake_environment(R, color(0.3, 0.45, 0.8), color(0.9, 0.9, 0.85),
                                     color(0.25, 0.2, 0.15));
        Cright = LocIllumCookTorrance(Nf, V, 0.25, F0_GOLD) +
                 fresnel_rgb(max(Nf . V, 0), F0_GOLD) * env * 0.5;
    }
    Oi = Os;
    Ci = Os * mix(Cleft, Cright, mroot);
}
