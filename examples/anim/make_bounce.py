#!/usr/bin/env python3
"""Writes bounce.rib: a keyframed bouncing ball and a spinning wheel, six frames in one RIB.

After Watt & Watt ch. 15 (keyframing): the ball's height is keyed at the top and the bottom
of each hop and interpolated between keys (a parabola per hop, ease-in/ease-out in height,
constant speed along x); squash and stretch is keyed on the scale at the contacts. Each frame
opens the shutter for half a frame (a 180° shutter at 24 fps) and gives every moving
transform as a MotionBegin block at the shutter's open and close times, so the renderer
blurs the motion inside the frame.  Run: python3 make_bounce.py > bounce.rib
"""
import math

FPS = 24.0
FRAMES = range(1, 7)
SHUTTER = 0.5 / FPS
HOP = 12.0 / FPS          # seconds per hop
SPEED = 4.8               # units per second along x
HEIGHT = 1.6


def ball(t):
    """Centre (x, y), squash (y scale) and roll angle of the ball at time t."""
    phase = (t % HOP) / HOP                # 0 at contact, 0.5 at the top
    y = 0.5 + HEIGHT * 4.0 * phase * (1.0 - phase)
    x = -3.0 + SPEED * t
    # Squash near the contact, stretch on the way: a key of 0.75 at the floor.
    near = min(phase, 1.0 - phase) * HOP * FPS    # frames from the contact
    squash = 0.75 + 0.25 * min(near / 1.5, 1.0)
    if near < 1.5:
        y -= 0.5 * (1.0 - squash)
    roll = -math.degrees(SPEED * t / 0.5)
    return x, y, squash, roll


def frame(n):
    t0 = (n - 1) * 2.0 / FPS   # every other frame of the 24 fps sequence
    t1 = t0 + SHUTTER
    b0, b1 = ball(t0), ball(t1)
    w0, w1 = 1080.0 * t0, 1080.0 * t1   # the wheel turns 3 times a second
    out = [f"FrameBegin {n}",
           f'Display "bounce.{n}.png" "png" "rgba"',
           "Format 240 160 1", "PixelSamples 4 4", 'Projection "perspective" "fov" [38]',
           f"Shutter {t0:.6f} {t1:.6f}",
           "Translate 0 -1.2 9", "Rotate -8 1 0 0",
           "WorldBegin",
           'LightSource "ambientlight" 1 "intensity" [0.25]',
           'LightSource "distantlight" 2 "intensity" [0.9] "from" [-2 4 -3] "to" [0 0 0]',
           "AttributeBegin", 'Surface "matte"', "Color [0.55 0.6 0.7]",
           'Polygon "P" [-6 0 -2  6 0 -2  6 0 6  -6 0 6]', "AttributeEnd",
           # The wheel behind: eight spokes and a rim, spinning about z.
           "AttributeBegin", "Translate 2.3 2.2 3", 'Surface "plastic"', "Color [0.9 0.8 0.3]",
           f"MotionBegin [{t0:.6f} {t1:.6f}]", f"Rotate {w0:.3f} 0 0 1", f"Rotate {w1:.3f} 0 0 1",
           "MotionEnd", "Torus 1.1 0.06 0 360 360"]
    for k in range(8):
        out += ["TransformBegin", f"Rotate {45 * k} 0 0 1",
                'Polygon "P" [0 -0.05 0  1.1 -0.05 0  1.1 0.05 0  0 0.05 0]', "TransformEnd"]
    out += ["AttributeEnd",
            "AttributeBegin", 'Surface "plastic" "Ks" [0.6]', "Color [0.9 0.25 0.1]",
            f"MotionBegin [{t0:.6f} {t1:.6f}]",
            f"Translate {b0[0]:.4f} {b0[1]:.4f} 0", f"Translate {b1[0]:.4f} {b1[1]:.4f} 0",
            "MotionEnd",
            f"MotionBegin [{t0:.6f} {t1:.6f}]",
            f"Scale {1 / math.sqrt(b0[2]):.4f} {b0[2]:.4f} {1 / math.sqrt(b0[2]):.4f}",
            f"Scale {1 / math.sqrt(b1[2]):.4f} {b1[2]:.4f} {1 / math.sqrt(b1[2]):.4f}",
            "MotionEnd",
            f"MotionBegin [{t0:.6f} {t1:.6f}]",
            f"Rotate {b0[3]:.3f} 0 0 1", f"Rotate {b1[3]:.3f} 0 0 1", "MotionEnd",
            'Surface "plastic" "Ks" [0.6]',
            "Sphere 0.5 -0.5 0.5 360",
            "AttributeEnd", "WorldEnd", "FrameEnd", ""]
    return "\n".join(out)


print("# bounce.rib: written by make_bounce.py (keyframed bounce and spinning wheel, motion blurred)")
for n in FRAMES:
    print(frame(n))
