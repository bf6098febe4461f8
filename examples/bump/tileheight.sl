/* A periodic height field for the bump-map example: rounded square tiles (height 1)
   separated by grout (height 0), with a little noise on the tile tops. Rendered as grey
   into a picture that MakeBump turns into a bump map. */
surface tileheight(float tiles = 4; float grout = 0.06; float soft = 0.04; float rough = 0.08)
{
    float ss = s * tiles, tt = t * tiles;
    float fs = ss - floor(ss), ft = tt - floor(tt);
    /* distance to the nearest tile edge, in tile units */
    float d = min(min(fs, 1 - fs), min(ft, 1 - ft));
    float h = smoothstep(grout * 0.5, grout * 0.5 + soft, d);
    /* periodic noise so the map still tiles */
    h *= 1 - rough + rough * float pnoise(point(ss * 4, tt * 4, 0), point(tiles * 4, tiles * 4, 1));
    Ci = h;
    Oi = 1;
}
