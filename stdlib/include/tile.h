/* tile.h -- anti-aliased tiles with grout: integratedpulse() and tile(), with the interface
 * of the header of the same name that Peter Quint's PQ shaders in the RenderMan Repository
 * include.  Written for arbor from the header's description (box filtering by differences of
 * the integral of the pattern, as Advanced RenderMan ch. 11 explains), not a copy of it.
 */
#ifndef TILE_H
#define TILE_H 1

/* The edge pattern along one axis: tiles of period pulseperiod, each with an edge band of
 * pulsewidth (a fraction of the period) split between its two ends.  Returns the integral
 * from 0 to x of the band's indicator (in x's units), and the tile x is in (which) and the
 * fraction of the way across it (offset). */
float integratedpulse (float x, pulseperiod, pulsewidth; output float which, offset)
{
    float f = x / pulseperiod;
    which = floor(f);
    offset = f - which;
    float half = pulsewidth / 2;
    /* band at the tile's start, flat interior, band at its end */
    float within = min(offset, half) + max(0, offset - (1 - half));
    return (which * pulsewidth + within) * pulseperiod;
}

/* The share of the footprint [ss, ss + sfiltwidth] x [tt, tt + tfiltwidth] that lies in the
 * grout of swidth x twidth tiles whose edge bands are sedge and tedge (fractions of the tile;
 * half at each side): the larger of the two axes' box-filtered band coverages, 1 all grout,
 * 0 all tile.  Also the tile (swhich, twhich) and the position inside it (soffset, toffset,
 * 0..1) of (ss, tt). */
float tile (float ss, tt, swidth, twidth, sfiltwidth, tfiltwidth, sedge, tedge;
            output float swhich, twhich, soffset, toffset)
{
    float sw = max(abs(sfiltwidth), 1.0e-6), tw = max(abs(tfiltwidth), 1.0e-6);
    float w0 = 0, o0 = 0;
    float sfar = integratedpulse(ss + sw, swidth, sedge, w0, o0);
    float tfar = integratedpulse(tt + tw, twidth, tedge, w0, o0);
    float sband = abs(sfar - integratedpulse(ss, swidth, sedge, swhich, soffset)) / sw;
    float tband = abs(tfar - integratedpulse(tt, twidth, tedge, twhich, toffset)) / tw;
    return max(sband, tband);
}

#endif /* TILE_H */
