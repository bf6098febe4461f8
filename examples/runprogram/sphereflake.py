#!/usr/bin/env python3
"""A RunProgram procedural (RISpec 3.2 §5.8): a sphereflake refined by detail.

arbor writes one line per procedural, "detail datablock", where detail is the raster area
of the procedural's bound; this program answers with RIB followed by the byte \\377 and
waits for the next line. Each request draws a unit sphere and, while the bound is still
big on screen, nine children a third the size that are procedurals themselves.
"""
import math
import sys

# Children: six around the equator, three on top (directions in the sphere's space).
DIRS = [(math.cos(a), math.sin(a), 0.0) for a in (k * math.pi / 3 for k in range(6))]
DIRS += [
    (0.5 * math.cos(a), 0.5 * math.sin(a), math.sqrt(0.75))
    for a in (math.pi / 6 + k * 2 * math.pi / 3 for k in range(3))
]
# A unit sphere with children 4/3 away at a third of the size reaches out to 2.
BOUND = "[-2 2 -2 2 -2 2]"
MIN_DETAIL = 150.0  # stop refining below this many square pixels


def reply(detail, level):
    out = ['Sphere 1 -1 1 360']
    if detail > MIN_DETAIL:
        for x, y, z in DIRS:
            # Rotate the child's pole onto its direction so its own crown faces outwards.
            tilt = math.degrees(math.acos(max(-1.0, min(1.0, z))))
            spin = math.degrees(math.atan2(y, x))
            out.append(
                'AttributeBegin Translate %g %g %g Rotate %g 0 0 1 Rotate %g 0 1 0 '
                'Scale 0.3333 0.3333 0.3333 Color %s '
                'Procedural "RunProgram" ["sphereflake.py" "%d"] %s AttributeEnd'
                % (4 / 3 * x, 4 / 3 * y, 4 / 3 * z, spin, tilt, colour(level + 1),
                   level + 1, BOUND)
            )
    return "\n".join(out) + "\n"


def colour(level):
    c = [(0.9, 0.85, 0.75), (0.85, 0.45, 0.3), (0.35, 0.6, 0.85), (0.5, 0.8, 0.4)]
    return "%g %g %g" % c[level % len(c)]


def main():
    out = sys.stdout.buffer
    while True:
        line = sys.stdin.readline()
        if not line:
            return
        detail, _, data = line.strip().partition(" ")
        out.write(reply(float(detail), int(data or "0")).encode())
        out.write(b"\xff")
        out.flush()


if __name__ == "__main__":
    main()
