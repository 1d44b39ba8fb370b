#!/usr/bin/env python3
"""Writes a closed icosphere OBJ with normals facing the centre (for the integrating sphere).

usage: tools/icosphere.py RADIUS SUBDIVISIONS OUT.obj
"""
import math
import sys


def icosphere(subdiv):
    t = (1 + 5 ** 0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
         (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    v = [tuple(c / math.sqrt(sum(x * x for x in p)) for c in p) for p in v]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
         (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdiv):
        cache = {}

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                p = [(x + y) / 2 for x, y in zip(v[a], v[b])]
                n = math.sqrt(sum(x * x for x in p))
                v.append(tuple(x / n for x in p))
                cache[key] = len(v) - 1
            return cache[key]

        nf = []
        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        f = nf
    return v, f


def main():
    radius, subdiv, out = float(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    v, f = icosphere(subdiv)
    with open(out, "w") as o:
        o.write(f"# icosphere, radius {radius} m, {subdiv} subdivisions, normals inward\n")
        for p in v:
            o.write("v %.9f %.9f %.9f\n" % tuple(radius * c for c in p))
        for a, b, c in f:
            # reversed winding: the geometric normal points to the centre
            o.write(f"f {a + 1} {c + 1} {b + 1}\n")


if __name__ == "__main__":
    main()
