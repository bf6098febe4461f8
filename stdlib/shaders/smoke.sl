/*
 * smoke.sl -- participating medium for Atmosphere/Interior, with the interface of the
 * `smoke` volume shader BMRT 2.x shipped (the scenes of the uberlight and light-blocker
 * papers name it with these parameters).
 *
 * Marches the viewing ray from `integstart` to the surface (or `integend`), in steps of
 * `stepsize` with a jittered start, and integrates by the trapezoid rule:
 *   extinction   tau   = integral of density
 *   in-scatter   light = integral of density * (light arriving at the point)
 * The background is attenuated by exp(-tau * scatter) per channel, and the light scattered
 * toward the eye is added, scaled by `lightscale`. With `use_noise` the density is modulated
 * by a few octaves of noise (`freq`, `octaves`, `smokevary`); extra octaves are only summed
 * where the medium is lit, where they can be seen.
 *
 * Written for arbor from the documented behaviour; not BMRT's source.
 */

volume
smoke (float density = 60;
       float integstart = 0, integend = 100;
       float stepsize = 0.1;
       float maxsteps = 10000;
       float debug = 0;
       float use_lighting = 1;
       float use_noise = 1;
       color scatter = 1;       /* per-channel extinction; (1, 2.25, 21) for a sky */
       float octaves = 3, freq = 1, smokevary = 1;
       float lightscale = 15;)
{
    /* The eye point and the viewing direction, in current and shader space. */
    point eye = P - I;
    point eye_sh = transform ("shader", eye);
    vector dir_sh = vtransform ("shader", I);
    float len = length (dir_sh);
    float stop = min (len, integend) - 0.0001;

    color medium = 0, cover = 0;
    float along = integstart + random () * stepsize;
    if (along < stop && stepsize > 0) {
        vector unit_sh = dir_sh / len;
        vector unit = vtransform ("shader", "current", unit_sh);
        float step = min (stepsize, stop - along);
        float prev_density = 0;
        color prev_light = 0;
        float count = 0;
        along += step;
        while (along <= stop && count < maxsteps) {
            point here = eye + along * unit;
            point here_sh = eye_sh + along * unit_sh;

            color arriving = 1;
            if (use_lighting != 0) {
                arriving = 0;
                illuminance (here, vector (0, 0, 1), PI) {
                    arriving += Cl;
                }
            }

            float local = density;
            if (use_noise != 0) {
                point q = here_sh * freq;
                float n = 2 * noise (q) - 1;
                if (comp (arriving, 0) + comp (arriving, 1) + comp (arriving, 2) > 0.01) {
                    float amp = 1, o;
                    for (o = 1; o < octaves; o += 1) {
                        amp *= 0.5;
                        q *= 2;
                        n += amp * (2 * noise (q) - 1);
                    }
                }
                local = density * smoothstep (-1, 1, smokevary * n);
            }

            /* This step's share, by the trapezoid rule. */
            float tau = 0.5 * step * (local + prev_density);
            color scattered = 0.5 * step * (arriving * local + prev_light * prev_density);
            color ext = -tau * scatter;
            color opacity = 1 - color (exp (comp (ext, 0)), exp (comp (ext, 1)),
                                       exp (comp (ext, 2)));
            medium += (1 - cover) * scattered * opacity;
            cover += (1 - cover) * opacity;

            prev_density = local;
            prev_light = arriving;
            step = max (min (step, stop - along), 0.005);
            along += step;
            count += 1;
        }
        if (debug > 0)
            printf ("smoke: %f steps, opacity %c\n", count, cover);
    }
    Ci = lightscale * medium + (1 - cover) * Ci;
    Oi = cover + (1 - cover) * Oi;
}
