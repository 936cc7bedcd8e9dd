#!/usr/bin/env python3
"""Writes a coloured copy of an OBJ mesh as a binary PLY (gzipped when the output ends in
.gz): per-vertex 8-bit RGB from a smooth procedural pattern (cow patches over a warm base,
so Spot looks like a cow), no normals. Standard library only.

    scripts/dev/paint.py shared/meshes/odedstein/spot.obj.gz assets/spot_colored.ply.gz

The demo's coloured model (assets/spot_colored.ply.gz) was made this way from Spot (Keenan
Crane, public domain). The pattern is deterministic: the same input gives the same bytes.
"""
import gzip
import math
import struct
import sys


def read_obj(path):
    opener = gzip.open if path.endswith(".gz") else open
    positions, faces = [], []
    with opener(path, "rt") as f:
        for line in f:
            w = line.split()
            if not w:
                continue
            if w[0] == "v":
                positions.append(tuple(float(x) for x in w[1:4]))
            elif w[0] == "f":
                idx = [int(c.split("/")[0]) for c in w[1:]]
                idx = [i - 1 if i > 0 else len(positions) + i for i in idx]
                for k in range(1, len(idx) - 1):
                    faces.append((idx[0], idx[k], idx[k + 1]))
    return positions, faces


def colour(p, lo, hi):
    t = [(p[a] - lo[a]) / max(hi[a] - lo[a], 1e-9) for a in range(3)]
    # A sum of a few incommensurate waves: patches where it is high.
    v = (math.sin(21.1 * t[0] + 2.0 * math.sin(9.3 * t[2]))
         + math.sin(17.7 * t[1] + 5.1 * t[0]) + math.sin(19.3 * t[2] - 7.2 * t[1]))
    s = 1.0 / (1.0 + math.exp(-8.0 * (v - 0.9)))  # soft patch edges
    base = (236, 214, 188)
    spot = (46, 38, 34)
    return tuple(int(round(base[c] * (1 - s) + spot[c] * s)) for c in range(3))


def main():
    src, out = sys.argv[1], sys.argv[2]
    positions, faces = read_obj(src)
    lo = [min(p[a] for p in positions) for a in range(3)]
    hi = [max(p[a] for p in positions) for a in range(3)]
    # The comment is the one in assets/spot_colored.ply.gz, so the same input gives its bytes.
    head = (
        "ply\nformat binary_little_endian 1.0\ncomment painted by scripts/paint.py from %s\n"
        "element vertex %d\nproperty float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        "element face %d\nproperty list uchar int vertex_indices\nend_header\n"
    ) % (src.rsplit("/", 1)[-1], len(positions), len(faces))
    body = bytearray(head.encode())
    for p in positions:
        body += struct.pack("<fffBBB", *p, *colour(p, lo, hi))
    for f in faces:
        body += struct.pack("<Biii", 3, *f)
    if out.endswith(".gz"):
        with open(out, "wb") as f:
            f.write(gzip.compress(bytes(body), 9, mtime=0))
    else:
        with open(out, "wb") as f:
            f.write(body)


if __name__ == "__main__":
    main()
