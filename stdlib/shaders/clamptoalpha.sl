/* BMRT's standard imager clamptoalpha: each colour channel is clamped to [0, alpha], so no
   pixel is brighter than its coverage allows (a premultiplied colour never exceeds its alpha).
   Scenes from BMRT-era exporters name it without shipping it. */
imager clamptoalpha()
{
    Ci = clamp(Ci, color(0, 0, 0), color(alpha, alpha, alpha));
}
