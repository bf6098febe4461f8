/* RISpec 3.2 Appendix A distantlight with a shadow map (orthographic depth render along
   to - from); the light is scaled by 1 - shadow(). */
light shadowdistant(float intensity = 1; color lightcolor = 1;
                    point from = point "shader" (0, 0, 0);
                    point to = point "shader" (0, 0, 1);
                    string shadowname = "";
                    float samples = 16; float blur = 0; float width = 1; float bias = 0.01;)
{
    solar(to - from, 0.0) {
        Cl = intensity * lightcolor;
        if (shadowname != "")
            Cl *= 1 - shadow(shadowname, Ps, "samples", samples, "blur", blur,
                             "width", width, "bias", bias);
    }
}
