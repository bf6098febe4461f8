#!/usr/bin/env python3
"""Writes examples/horizon_bumps.png: a periodic 16-bit height map (wavy ridges plus round
bumps) for the horizon-mapping example. Pure Python (zlib PNG writer), deterministic."""
import math, random, struct, zlib, sys

N = 128
random.seed(7)
blobs = [(random.random(), random.random(), 0.03 + 0.03 * random.random()) for _ in range(10)]

def height(s, t):
    # Ridges running along t, wobbling (integer frequencies keep the map periodic).
    r = 0.5 + 0.5 * math.sin(2 * math.pi * (4 * s + 0.25 * math.sin(2 * math.pi * 2 * t)))
    h = 0.6 * r ** 3
    for (bs, bt, rad) in blobs:
        ds = (s - bs + 0.5) % 1.0 - 0.5
        dt = (t - bt + 0.5) % 1.0 - 0.5
        h = max(h, 0.9 * math.exp(-(ds * ds + dt * dt) / (rad * rad)))
    return min(1.0, h)

rows = b""
for y in range(N):
    rows += b"\x00" + b"".join(
        struct.pack(">H", int(65535 * height((x + 0.5) / N, (y + 0.5) / N))) for x in range(N))
def chunk(tag, data):
    c = tag + data
    return struct.pack(">I", len(data)) + c + struct.pack(">I", zlib.crc32(c) & 0xffffffff)
png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", N, N, 16, 0, 0, 0, 0)) \
    + chunk(b"IDAT", zlib.compress(rows, 9)) + chunk(b"IEND", b"")
out = sys.argv[1] if len(sys.argv) > 1 else "examples/horizon_bumps.png"
open(out, "wb").write(png)
