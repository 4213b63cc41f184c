#!/usr/bin/env python3
"""Writes assets/models/pioneer.obj and pioneer.mtl: a small Pioneer 3-DX-like robot
made of boxes and prisms (mm, x ahead, y left, z up, origin at the centre of the
wheel axle on the floor). Licensed as the project (GPL-3.0-or-later); see
assets/models/README.md. Run from the repository root."""
import math

out = []          # OBJ lines
nv = 0            # vertices written so far


def v(p):
    global nv
    out.append("v %.1f %.1f %.1f" % p)
    nv += 1
    return nv


def box(name, mat, x0, x1, y0, y1, z0, z1):
    out.append("o %s" % name)
    out.append("usemtl %s" % mat)
    idx = [v((x, y, z)) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)]
    # corners: i = x + 2y + 4z
    for f in ((0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)):
        out.append("f " + " ".join(str(idx[k]) for k in f))


def wheel(name, mat, yc, width, r, sides=12):
    """A wheel: a prism about the y axis centred at (0, yc, r)."""
    out.append("o %s" % name)
    out.append("usemtl %s" % mat)
    rings = []
    for y in (yc - width / 2, yc + width / 2):
        ring = []
        for k in range(sides):
            a = 2 * math.pi * k / sides
            ring.append(v((r * math.cos(a), y, r + r * math.sin(a))))
        rings.append(ring)
    for k in range(sides):
        a, b = rings[0][k], rings[0][(k + 1) % sides]
        c, d = rings[1][(k + 1) % sides], rings[1][k]
        out.append("f %d %d %d %d" % (a, b, c, d))
    out.append("f " + " ".join(str(i) for i in reversed(rings[0])))
    out.append("f " + " ".join(str(i) for i in rings[1]))


out.append("# Pioneer 3-DX-like robot for jderobot's opengl_viewer (mm; x ahead, y left, z up).")
out.append("# Made by scripts/make_pioneer_obj.py; licence: GPL-3.0-or-later, as jderobot.")
out.append("mtllib pioneer.mtl")
box("chassis", "pioneer_red", -220, 220, -150, 150, 60, 220)
box("top_plate", "plate_black", -235, 235, -170, 170, 220, 240)
box("bumper_front", "plate_black", 220, 240, -140, 140, 70, 140)
box("bumper_rear", "plate_black", -240, -220, -140, -80, 70, 140)
box("bumper_rear2", "plate_black", -240, -220, 80, 140, 70, 140)
wheel("wheel_left", "tyre_black", 180, 47, 97.5)
wheel("wheel_right", "tyre_black", -180, 47, 97.5)
box("caster", "tyre_black", -200, -160, -20, 20, 0, 60)
box("laser_base", "laser_blue", -40, 110, -75, 75, 240, 390)
box("laser_window", "plate_black", 80, 112, -60, 60, 280, 330)
box("pantilt", "plate_black", 165, 215, -25, 25, 390, 460)
box("camera", "camera_grey", 160, 235, -40, 40, 460, 520)
open("assets/models/pioneer.obj", "w").write("\n".join(out) + "\n")

open("assets/models/pioneer.mtl", "w").write("""# Materials of pioneer.obj (jderobot; GPL-3.0-or-later).
newmtl pioneer_red
Kd 0.80 0.10 0.10

newmtl plate_black
Kd 0.15 0.15 0.15

newmtl tyre_black
Kd 0.08 0.08 0.08

newmtl laser_blue
Kd 0.15 0.30 0.75

newmtl camera_grey
Kd 0.55 0.55 0.60
""")
