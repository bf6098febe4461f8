/* RISpec 3.2 Appendix A spotlight with a shadow map (as in the RenderMan Companion's
   shadowspot): the map is looked up with percentage-closer filtering; shadow() returns the
   fraction in shadow, so the light is scaled by 1 - shadow(). */
light shadowspot(float intensity = 1; color lightcolor = 1;
                 point from = point "shader" (0, 0, 0);
                 point to = point "shader" (0, 0, 1);
                 float coneangle = radians(30);
                 float conedeltaangle = radians(5);
                 float beamdistribution = 2;
                 string shadowname = "";
                 float samples = 16; float blur = 0; float width = 1; float bias = 0.01;)
{
    uniform vector A = (to - from) / length(to - from);
    uniform float cosoutside = cos(coneangle);
    uniform float cosinside = cos(coneangle - conedeltaangle);
    illuminate(from, A, coneangle) {
        float cosangle = L . A / length(L);
        float atten = pow(cosangle, beamdistribution) / (L . L);
        atten *= smoothstep(cosoutside, cosinside, cosangle);
        if (shadowname != "")
            atten *= 1 - shadow(shadowname, Ps, "samples", samples, "blur", blur,
                                "width", width, "bias", bias);
        Cl = atten * intensity * lightcolor;
    }
}
