#!/usr/bin/env python3
"""Writes scenes/head.obj: the head the procedural styles grow on (a sphere
of radius 10 at the origin) with a longer jaw, a nose and a neck, as a
closed triangle mesh. Run from the repository root: python3 scenes/make_head.py"""
import math

RINGS, SEGMENTS = 40, 64


def head(theta, phi):
    """Point of the head surface at polar angle theta (0 at the crown) and
    azimuth phi (0 towards +x, pi/2 towards +z, the face)."""
    x, y, z = math.sin(theta) * math.cos(phi), math.cos(theta), math.sin(theta) * math.sin(phi)
    r = 10.0
    if y < 0:  # jaw and chin: the lower half longer and narrower
        y *= 1.3
        x *= 1.0 + 0.12 * y
        z *= 1.0 + 0.05 * y
    # A nose: a bump on the face below the middle.
    d2 = (phi - math.pi / 2) ** 2 * 6 + (theta - 1.85) ** 2 * 10
    bump = 0.3 * math.exp(-d2 * 8)
    return (r * x, r * y, r * z + r * bump)


verts, faces = [], []
verts.append(head(0.0, 0.0))
for i in range(1, RINGS):
    theta = math.pi * i / RINGS
    for j in range(SEGMENTS):
        verts.append(head(theta, 2 * math.pi * j / SEGMENTS))
bottom = len(verts)
verts.append(head(math.pi, 0.0))


def ring(i, j):
    return 2 + (i - 1) * SEGMENTS + j % SEGMENTS  # 1-based OBJ index


for j in range(SEGMENTS):
    faces.append((1, ring(1, j + 1), ring(1, j)))
    for i in range(1, RINGS - 1):
        faces.append((ring(i, j), ring(i, j + 1), ring(i + 1, j)))
        faces.append((ring(i, j + 1), ring(i + 1, j + 1), ring(i + 1, j)))
    faces.append((bottom + 1, ring(RINGS - 1, j), ring(RINGS - 1, j + 1)))

# The neck: a closed cylinder of radius 4.5 from inside the head down.
NECK = len(verts)
for y in (-6.0, -24.0):
    for j in range(SEGMENTS):
        a = 2 * math.pi * j / SEGMENTS
        verts.append((4.5 * math.cos(a), y, 4.5 * math.sin(a) - 1.0))
top, low = NECK + 1, NECK + SEGMENTS + 1
verts.append((0.0, -24.0, -1.0))
cap = len(verts)
for j in range(SEGMENTS):
    k = (j + 1) % SEGMENTS
    faces.append((top + j, low + j, top + k))
    faces.append((top + k, low + j, low + k))
    faces.append((cap, low + k, low + j))

with open("scenes/head.obj", "w") as f:
    f.write("# A head for wisplight's procedural styles (radius 10 at the origin), made by scenes/make_head.py\n")
    for v in verts:
        f.write("v %.4f %.4f %.4f\n" % v)
    for t in faces:
        f.write("f %d %d %d\n" % t)
