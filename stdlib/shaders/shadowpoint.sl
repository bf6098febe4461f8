/* RISpec 3.2 Appendix A pointlight with six shadow maps, one per axis direction from the
   light (90-degree depth renders along +x -x +y -y +z -z of shader space, as for cube-face
   environments): the map is chosen by the dominant axis of the light-to-point vector.
   BMRT's form `shadowname` (one name, or "raytrace" for ray-traced shadows) wins when set. */
light shadowpoint(float intensity = 1; color lightcolor = 1;
                  point from = point "shader" (0, 0, 0);
                  string sfpx = ""; string sfnx = "";
                  string sfpy = ""; string sfny = "";
                  string sfpz = ""; string sfnz = "";
                  string shadowname = "";
                  float samples = 16; float blur = 0; float width = 1; float bias = 0.01;)
{
    illuminate(from) {
        Cl = intensity * lightcolor / (L . L);
        vector D = vtransform("shader", -L);
        float ax = abs(xcomp(D));
        float ay = abs(ycomp(D));
        float az = abs(zcomp(D));
        string sm = "";
        if (shadowname != "")
            sm = shadowname;
        else if (ax >= ay && ax >= az) {
            if (xcomp(D) > 0) sm = sfpx; else sm = sfnx;
        } else if (ay >= az) {
            if (ycomp(D) > 0) sm = sfpy; else sm = sfny;
        } else {
            if (zcomp(D) > 0) sm = sfpz; else sm = sfnz;
        }
        if (sm != "")
            Cl *= 1 - shadow(sm, Ps, "samples", samples, "blur", blur, "width", width,
                             "bias", bias);
    }
}
