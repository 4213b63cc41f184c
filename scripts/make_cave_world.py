#!/usr/bin/env python3
"""Writes assets/worlds/cave.world: an irregular cave (after Stage's `cave` map) of
about a hundred wall faces, for the 3D panels' benchmark and examples. The shape
is a fixed pseudo-random outline (seeded), so the file is reproducible. Run from
the repository root."""
import math
import random

rnd = random.Random(43)
walls = []


def ring(cx, cy, rx, ry, n, jitter):
    pts = []
    for k in range(n):
        a = 2 * math.pi * k / n
        f = 1 + rnd.uniform(-jitter, jitter)
        pts.append((cx + rx * f * math.cos(a), cy + ry * f * math.sin(a)))
    return pts


def close(pts):
    for k in range(len(pts)):
        (x1, y1), (x2, y2) = pts[k], pts[(k + 1) % len(pts)]
        walls.append("wall %d %d %d %d" % (x1, y1, x2, y2))


close(ring(0, 0, 9000, 6500, 48, 0.12))
for cx, cy, r in [(-5000, 2500, 900), (-4500, -3000, 700), (4200, 3000, 1000),
                  (5200, -2500, 800), (1500, -4200, 600), (-1200, 4300, 650),
                  (2500, 700, 500), (-2600, -300, 550)]:
    close(ring(cx, cy, r, r * 0.8, 8, 0.2))

text = ["# cave.world: an irregular cave (after Stage's `cave` map), 18 m x 13 m, with",
        "# eight rock pillars; about a hundred wall faces. Made by scripts/make_cave_world.py.",
        "wall_height 1200", "wall_color 125,105,85", "floor_color 150,145,135",
        "floor_tile 0", "sky_color 40,40,48", ""] + walls + ["", "start 0 0 0", "start 0 2000 90"]
open("assets/worlds/cave.world", "w").write("\n".join(text) + "\n")
