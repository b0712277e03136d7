#!/usr/bin/env python3
"""How close a matched surface came to its target, judged without fshape.

    python3 scripts/pair_quality.py MATCHED.ply TARGET.ply

Reads the two PLY files (ASCII or binary little-endian, triangles, a
per-vertex `signal` and optional `mask` as fshape writes them; the
native-resolution benchmark writes matched.ply and target.ply) with numpy
alone and prints, as percentages:

- the mean and 95th percentile distance from each target vertex to the
  matched surface, and the share of target vertices within 1 % of the
  target's bounding-box diagonal;
- the signal error: the rms, over target vertices that carry a value
  (mask > 0.5, not NaN), of the target's signal minus the matched signal
  there, as a share of the target signal's range.

The matched surface is represented by samples (its vertices, edge
midpoints and triangle centroids, the signal interpolated linearly), and a
distance is to the nearest sample: it overestimates the distance to the
surface by at most half the longest edge, which the script prints beside
the figures. Masked matched samples (a corner under 0.5) give no signal.
Brute force in chunks: meant for pairs of up to ~50 000 vertices.
"""

import sys

import numpy as np

TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


def read_ply(path):
    """(points n x 3, triangles m x 3, vertex properties by name)."""
    data = open(path, "rb").read()
    end = data.index(b"end_header") + len(b"end_header")
    end = data.index(b"\n", end) + 1
    header = data[:end].decode("ascii").splitlines()
    fmt = header[1].split()[1]
    elements = []
    for line in header:
        words = line.split()
        if words[0] == "element":
            elements.append([words[1], int(words[2]), []])
        elif words[0] == "property":
            elements[-1][2].append(words[1:])
    body = data[end:]
    props, faces = {}, None
    if fmt == "ascii":
        rows = iter(body.decode("ascii").split("\n"))
        for name, count, fields in elements:
            lines = [next(rows).split() for _ in range(count)]
            if name == "vertex":
                table = np.array(lines, dtype=float)
                props = {f[-1]: table[:, k] for k, f in enumerate(fields)}
            elif name == "face":
                faces = np.array([[int(v) for v in l[1:4]] for l in lines])
        return np.column_stack([props["x"], props["y"], props["z"]]), faces, props
    if fmt != "binary_little_endian":
        sys.exit(f"{path}: {fmt} PLY is not read here")
    offset = 0
    for name, count, fields in elements:
        if name == "vertex":
            dtype = np.dtype([(f[-1], "<" + TYPES[f[0]]) for f in fields])
            table = np.frombuffer(body, dtype=dtype, count=count, offset=offset)
            offset += dtype.itemsize * count
            props = {n: table[n].astype(float) for n in dtype.names}
        elif name == "face":
            (_, length, index, _), = fields
            ld, idx = np.dtype("<" + TYPES[length]), np.dtype("<" + TYPES[index])
            row = np.dtype([("n", ld), ("v", idx, (3,))])
            table = np.frombuffer(body, dtype=row, count=count, offset=offset)
            if (table["n"] != 3).any():
                sys.exit(f"{path}: only triangles are read here")
            faces = table["v"].astype(np.int64)
            offset += row.itemsize * count
    return np.column_stack([props["x"], props["y"], props["z"]]), faces, props


def samples(points, faces, signal, mask):
    """Vertices, edge midpoints and centroids with their signal (NaN where
    a corner is masked)."""
    f = np.where(mask > 0.5, signal, np.nan)
    edges = np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1), axis=0)
    xs = [points, points[edges].mean(axis=1), points[faces].mean(axis=1)]
    fs = [f, f[edges].mean(axis=1), f[faces].mean(axis=1)]
    longest = np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1).max()
    return np.concatenate(xs), np.concatenate(fs), longest


def nearest(queries, xs, chunk=128):
    """Index and distance of each query's nearest sample."""
    index = np.empty(len(queries), dtype=np.int64)
    dist = np.empty(len(queries))
    sq = (xs * xs).sum(axis=1)
    for start in range(0, len(queries), chunk):
        q = queries[start:start + chunk]
        d2 = sq[None, :] - 2.0 * q @ xs.T + (q * q).sum(axis=1)[:, None]
        k = d2.argmin(axis=1)
        index[start:start + chunk] = k
        dist[start:start + chunk] = np.linalg.norm(xs[k] - q, axis=1)
    return index, dist


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    matched, target = read_ply(sys.argv[1]), read_ply(sys.argv[2])
    (mx, mf, mp), (tx, _, tp) = matched, target
    one = lambda p, n: p.get(n, np.ones(len(p["x"])))
    xs, fs, longest = samples(mx, mf, mp["signal"], one(mp, "mask"))
    diagonal = np.linalg.norm(tx.max(axis=0) - tx.min(axis=0))
    k, d = nearest(tx, xs)
    print(f"target: {len(tx)} vertices, diagonal {diagonal:.2f}; matched: {len(mx)} vertices, "
          f"{len(xs)} samples (distances high by at most {0.5 * longest:.3f}, "
          f"{100 * 0.5 * longest / diagonal:.3f} % of the diagonal)")
    print(f"mean distance {100 * d.mean() / diagonal:.3f} %, 95th percentile "
          f"{100 * np.percentile(d, 95) / diagonal:.3f} % of the diagonal; "
          f"{100 * (d <= 0.01 * diagonal).mean():.1f} % of the target within 1 %")
    tf = np.where(one(tp, "mask") > 0.5, tp["signal"], np.nan)
    valid = ~np.isnan(tf) & ~np.isnan(fs[k])
    span = np.nanmax(tf) - np.nanmin(tf)
    rms = np.sqrt(np.mean((tf[valid] - fs[k][valid]) ** 2))
    print(f"signal error {100 * rms / span:.2f} % of the target's range (rms over {valid.sum()} vertices "
          f"with a value on both sides)")


if __name__ == "__main__":
    main()
