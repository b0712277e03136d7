"""The binary PLY reader and the lumped areas shared by this folder's diagnostics."""
import re
import sys

import numpy as np


def read_ply(path):
    """Positions (P x 3), signal (P, or None without a `signal` property) and
    triangles (T x 3) of a binary little-endian PLY with double vertex
    properties x, y, z[, signal], as fshape writes them."""
    b = open(path, "rb").read()
    end = b.index(b"end_header\n") + len(b"end_header\n")
    hdr = b[:end].decode()
    nv = int(re.search(r"element vertex (\d+)", hdr).group(1))
    nf = int(re.search(r"element face (\d+)", hdr).group(1))
    props = re.findall(r"property double (\w+)", hdr)
    if props[:3] != ["x", "y", "z"] or "binary_little_endian" not in hdr:
        sys.exit(f"{path}: expected a binary little-endian PLY with double x, y, z")
    v = np.frombuffer(b, dtype="<f8", count=nv * len(props), offset=end).reshape(nv, len(props))
    off = end + nv * len(props) * 8
    faces = np.frombuffer(b, dtype=np.dtype([("n", "u1"), ("i", "<i4", (3,))]), count=nf, offset=off)
    if np.any(faces["n"] != 3):
        sys.exit(f"{path}: only triangles are read")
    signal = v[:, props.index("signal")].copy() if "signal" in props else None
    return v[:, :3].copy(), signal, faces["i"].astype(np.int64)


def lumped_areas(x, f):
    """A third of the area of the triangles around each vertex."""
    a = 0.5 * np.linalg.norm(np.cross(x[f[:, 1]] - x[f[:, 0]], x[f[:, 2]] - x[f[:, 0]]), axis=1)
    m = np.zeros(len(x))
    for k in range(3):
        np.add.at(m, f[:, k], a / 3)
    return m
