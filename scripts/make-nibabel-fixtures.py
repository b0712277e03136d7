#!/usr/bin/env python3
"""Writes the GIfTI and FreeSurfer fixtures of fshape-mesh/tests/data/nibabel
with nibabel (the field's reader and writer), and the arrays they hold as
plain CSV for the Rust tests to compare against.

Run it through scripts/make-nibabel-fixtures.sh, which makes a venv with
nibabel first. The mesh is an icosahedron with coordinates that are not
round in binary, so that a reader mixing up byte orders or index orders
cannot pass by luck; every value is a float32, as these formats store.

nibabel writes GIfTI only in the machine's byte order; the big-endian file
is made by nibabel's writer with the data byte-swapped and the Endian
attribute set to match, and is checked by nibabel's reader like the rest.
"""
import os
import sys

import nibabel as nib
import nibabel.gifti.gifti as ngifti
import numpy as np

out = sys.argv[1]
os.makedirs(out, exist_ok=True)

t = (1.0 + 5.0**0.5) / 2.0
points = np.array(
    [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0],
     [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
     [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], dtype=np.float64)
points = (points * 0.7310585786 + np.array([12.25, -3.5, 0.125])).astype(np.float32)
faces = np.array(
    [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
     [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
     [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
     [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]], dtype=np.int32)
thickness = (2.5 + np.sin(np.arange(12) * 1.3) / 3.0).astype(np.float32)


def csv(name, header, rows):
    with open(os.path.join(out, name), "w") as f:
        f.write(header + "\n")
        for r in np.atleast_2d(rows.T).T if rows.ndim == 1 else rows:
            f.write(",".join(repr(float(v)) for v in np.atleast_1d(r)) + "\n")


csv("expected_points.csv", "x,y,z", points)
csv("expected_faces.csv", "a,b,c", faces)
csv("expected_thickness.csv", "thickness", thickness)

encodings = {"ascii": "ASCII", "base64": "B64BIN", "gzipbase64": "B64GZ"}


def surface(encoding, order="RowMajorOrder"):
    meta = nib.gifti.GiftiMetaData({"Name": "thickness"})
    return nib.gifti.GiftiImage(darrays=[
        nib.gifti.GiftiDataArray(points, intent="NIFTI_INTENT_POINTSET", datatype="NIFTI_TYPE_FLOAT32",
                                 encoding=encoding, ordering=order),
        nib.gifti.GiftiDataArray(faces, intent="NIFTI_INTENT_TRIANGLE", datatype="NIFTI_TYPE_INT32",
                                 encoding=encoding, ordering=order),
        nib.gifti.GiftiDataArray(thickness, intent="NIFTI_INTENT_SHAPE", datatype="NIFTI_TYPE_FLOAT32",
                                 encoding=encoding, meta=meta),
    ])


def shape(encoding, datatype="NIFTI_TYPE_FLOAT32"):
    data = thickness.astype(np.float64) if datatype.endswith("FLOAT64") else thickness
    return nib.gifti.GiftiImage(darrays=[nib.gifti.GiftiDataArray(
        data, intent="NIFTI_INTENT_SHAPE", datatype=datatype, encoding=encoding,
        meta=nib.gifti.GiftiMetaData({"Name": "thickness"}))])


files = {}
for name, enc in encodings.items():
    files[f"surf_{name}.surf.gii"] = surface(enc)
    files[f"thickness_{name}.shape.gii"] = shape(enc)
files["surf_colmajor_gzipbase64.surf.gii"] = surface("B64GZ", "ColumnMajorOrder")
files["thickness_float64.func.gii"] = shape("B64BIN", "NIFTI_TYPE_FLOAT64")
for name, img in files.items():
    # GIfTI allows FLOAT32, INT32 and UINT8; "force" writes FLOAT64 as asked.
    img.to_filename(os.path.join(out, name), mode="force")

# Big endian: nibabel's writer, with the byte order switched.
real_tag, real_to_xml = ngifti._data_tag_element, ngifti.GiftiDataArray._to_xml_element


def big_tag(dataarray, encoding, dtype, ordering):
    return real_tag(np.asarray(dataarray, dtype).astype(np.dtype(dtype).newbyteorder(">")).view(dtype),
                    encoding, dtype, ordering)


def big_to_xml(self):
    el = real_to_xml(self)
    el.attrib["Endian"] = "BigEndian"
    return el


ngifti._data_tag_element, ngifti.GiftiDataArray._to_xml_element = big_tag, big_to_xml
nib.save(surface("B64GZ"), os.path.join(out, "surf_bigendian_gzipbase64.surf.gii"))
nib.save(shape("B64BIN"), os.path.join(out, "thickness_bigendian_base64.shape.gii"))
ngifti._data_tag_element, ngifti.GiftiDataArray._to_xml_element = real_tag, real_to_xml

nib.freesurfer.write_geometry(os.path.join(out, "lh.icosahedron"), points, faces, create_stamp="created by nibabel")
nib.freesurfer.write_morph_data(os.path.join(out, "lh.thickness"), thickness, fnum=len(faces))
for ext in ("mgh", "mgz"):
    nib.save(nib.MGHImage(thickness.reshape(-1, 1, 1), np.eye(4)), os.path.join(out, f"thickness.{ext}"))

# nibabel reads every file back to the same arrays (the big-endian ones
# included), so the fixtures are what they claim to be. nibabel writes
# ASCII floats with six decimals ('%10.6f'): those match to 5e-7.
for name in sorted(os.listdir(out)):
    path = os.path.join(out, name)
    if "ascii" in name:
        np_equal = lambda a, b: np.allclose(a, b, rtol=0, atol=5e-7)  # noqa: E731
    else:
        np_equal = np.array_equal
    if name.endswith(".surf.gii"):
        g = nib.load(path)
        p = g.agg_data("pointset")
        f = g.agg_data("triangle")
        s = g.agg_data("shape")
        assert np_equal(p, points) and np_equal(f, faces) and np_equal(s, thickness), name
    elif name.endswith(".gii"):
        assert np_equal(nib.load(path).darrays[0].data, thickness), name
    elif name == "lh.icosahedron":
        p, f = nib.freesurfer.read_geometry(path)
        assert np_equal(p, points) and np_equal(f, faces), name
    elif name == "lh.thickness":
        assert np_equal(nib.freesurfer.read_morph_data(path), thickness), name
    elif name.startswith("thickness.mg"):
        assert np_equal(np.asarray(nib.load(path).dataobj).ravel(), thickness), name
print(f"wrote {len(os.listdir(out))} files to {out} with nibabel {nib.__version__}")
