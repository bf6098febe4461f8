#!/usr/bin/env python3
"""Writes a geometry-bound benchmark RIB: N small coloured quads (each its own Polygon) on a
wavy sheet, deterministic. Also the memory benchmark (a 4K frame with dense geometry) and the
parse-bound one (a large RIB), by options:

    python3 examples/bench/gen_polys.py > /tmp/polys.rib                  # 100 000 polygons
    python3 examples/bench/gen_polys.py --format 4096 3112 --count 1000000 > /tmp/4k.rib
    python3 examples/bench/gen_polys.py --count 370000 > /tmp/big.rib    # about 50 MB
"""
import math, sys

count, xres, yres = 100_000, 1280, 960
args = sys.argv[1:]
while args:
    a = args.pop(0)
    if a == "--count":
        count = int(args.pop(0))
    elif a == "--format":
        xres, yres = int(args.pop(0)), int(args.pop(0))
    else:
        sys.exit(f"unknown option {a}")

side = max(1, int(math.sqrt(count * xres / yres)))
rows = max(1, count // side)
w = 4.0
h = w * yres / xres
out = sys.stdout
out.write("##RenderMan RIB-Structure 1.1\n")
out.write(f"# {side * rows} small polygons (examples/bench/gen_polys.py)\n")
out.write('Display "polys.png" "png" "rgb"\n')
out.write(f"Format {xres} {yres} 1\nPixelSamples 4 4\nPixelFilter \"gaussian\" 2 2\nShadingRate 1\n")
out.write('Projection "orthographic"\n')
out.write(f"ScreenWindow {-w / 2:.4f} {w / 2:.4f} {-h / 2:.4f} {h / 2:.4f}\n")
out.write("Translate 0 0 5\nWorldBegin\n")
out.write('LightSource "ambientlight" 1 "intensity" [0.2]\n')
out.write('LightSource "distantlight" 2 "intensity" [0.8] "from" [-1 1 -2] "to" [0 0 0]\n')
out.write('Surface "plastic"\n')
dx, dy = w / side, h / rows
for j in range(rows):
    y0 = -h / 2 + j * dy
    for i in range(side):
        x0 = -w / 2 + i * dx
        # Slightly overlapping quads at varying depth: real visibility work.
        z = 0.3 * math.sin(3.1 * x0 + 1.7 * y0)
        r = 0.5 + 0.5 * math.sin(1.3 * i)
        g = 0.5 + 0.5 * math.sin(0.7 * j)
        x1, y1 = x0 + dx * 1.2, y0 + dy * 1.2
        out.write(f"Color [{r:.3f} {g:.3f} 0.5]\n")
        out.write(f"Polygon \"P\" [{x0:.5f} {y0:.5f} {z:.4f} {x1:.5f} {y0:.5f} {z:.4f} "
                  f"{x1:.5f} {y1:.5f} {z:.4f} {x0:.5f} {y1:.5f} {z:.4f}]\n")
out.write("WorldEnd\n")
