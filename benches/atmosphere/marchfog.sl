/* marchfog: a ray-marched participating medium lit by the scene's lights.
 *
 * From the eye to the surface point, steps of `stepsize` (the last one shortened to end
 * at the surface); at each step the light arriving at the step point is gathered with
 * illuminance() and scattered toward the eye by a noisy density, attenuated by what lies
 * in front. Written for arbor's atmosphere benchmark.
 */
volume marchfog(float density = 0.08, scattering = 0.6;
                float stepsize = 0.25, maxdist = 40;
                float noisefreq = 0.7, noiseamount = 0.8;)
{
    point eye = P - I;
    vector dir = normalize(I);
    float len = min(length(I), maxdist);
    float d = 0, step = stepsize, trans = 1;
    color glow = 0;
    while (d < len && trans > 0.002) {
        step = min(stepsize, len - d);
        point here = eye + (d + 0.5 * step) * dir;
        color arriving = 0;
        illuminance(here) {
            arriving += Cl;
        }
        point q = transform("shader", here) * noisefreq;
        float dens = density * (1 - noiseamount + noiseamount * 2 * noise(q));
        float absorbed = 1 - exp(-max(dens, 0) * step);
        glow += trans * absorbed * scattering * arriving;
        trans *= 1 - absorbed;
        d += step;
    }
    Ci = glow + trans * Ci;
    Oi = (1 - trans) + trans * Oi;
}
