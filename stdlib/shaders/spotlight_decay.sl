/* RISpec's spotlight with its distance falloff as 1/distance^decay (Maya's decay: 0 none,
 * 1 linear, 2 quadratic, which is spotlight's). arbor stands it in for a missing light shader
 * whose instance gives a cone and a "decay" (e.g. Liquid's liquidspot). */
light spotlight_decay(float intensity = 1; color lightcolor = 1;
                      point from = point "shader" (0, 0, 0);
                      point to = point "shader" (0, 0, 1);
                      float coneangle = radians(30);
                      float conedeltaangle = radians(5);
                      float beamdistribution = 2;
                      float decay = 2;)
{
    uniform vector A = (to - from) / length(to - from);
    uniform float cosoutside = cos(coneangle);
    uniform float cosinside = cos(coneangle - conedeltaangle);
    illuminate(from, A, coneangle) {
        float cosangle = L . A / length(L);
        float atten = pow(cosangle, beamdistribution) / pow(L . L, decay / 2);
        atten *= smoothstep(cosoutside, cosinside, cosangle);
        Cl = atten * intensity * lightcolor;
    }
}
