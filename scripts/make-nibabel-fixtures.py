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

# A parcellation: FreeSurfer's .annot (new layout) and a GIfTI label array
# with its label table. Two vertices belong to no region (-1 in .annot; key
# 0, "???", in the GIfTI as HCP writes its medial wall).
parcel = np.array([0, 0, 1, 1, 2, -1, 0, 1, 2, 2, -1, 1], dtype=np.int32)
names = ["precentral", "postcentral", "insula"]
ctab = np.array([[220, 20, 10, 0], [20, 220, 60, 0], [255, 192, 32, 0]], dtype=np.int32)
nib.freesurfer.write_annot(os.path.join(out, "lh.parcels.annot"), parcel, ctab, names)
csv("expected_parcels.csv", "key", parcel)
table = nib.gifti.GiftiLabelTable()
for key, name, rgba in [(0, "???", (0, 0, 0, 0)), (4, "precentral", (0.8, 0.1, 0.05, 1)),
                        (7, "postcentral", (0.1, 0.8, 0.25, 1)), (9, "insula", (1, 0.75, 0.125, 1))]:
    label = nib.gifti.GiftiLabel(key, *rgba)
    label.label = name
    table.labels.append(label)
gifti_keys = np.array([4, 7, 9, 0], dtype=np.int32)[np.where(parcel < 0, 3, parcel)]
nib.save(nib.gifti.GiftiImage(labeltable=table, darrays=[nib.gifti.GiftiDataArray(
    gifti_keys, intent="NIFTI_INTENT_LABEL", datatype="NIFTI_TYPE_INT32", encoding="B64GZ")]),
    os.path.join(out, "parcels.label.gii"))
csv("expected_label_gii_keys.csv", "key", gifti_keys)

# CIFTI-2 dense scalars as HCP writes them: CORTEX_LEFT without a "medial
# wall" (vertices 5 and 10), CORTEX_RIGHT on another 12-vertex surface
# without vertex 0, and two thalamus voxels, in two named maps.
ax = nib.cifti2.cifti2_axes
left = np.flatnonzero(parcel >= 0)
right = np.arange(1, 12)
voxels = np.array([[1, 2, 3], [2, 2, 3]])
brain = (ax.BrainModelAxis.from_surface(left, 12, "CortexLeft")
         + ax.BrainModelAxis.from_surface(right, 12, "CortexRight")
         + ax.BrainModelAxis("thalamus_left", voxel=voxels, affine=np.eye(4), volume_shape=(4, 4, 4)))
myelin = (1.25 + np.cos(np.arange(12) * 0.7) / 4.0).astype(np.float32)
right_thickness = (3.0 - np.sin(np.arange(12) * 0.9) / 5.0).astype(np.float32)
maps = np.vstack([
    np.concatenate([thickness[left], right_thickness[right], [7.5, 8.5]]),
    np.concatenate([myelin[left], myelin[right] + 1, [9.5, 10.5]]),
]).astype(np.float32)
cifti = nib.Cifti2Image(maps, header=(ax.ScalarAxis(["thickness", "myelin"]), brain))
cifti.nifti_header.set_intent("ConnDenseScalar")
cifti.to_filename(os.path.join(out, "maps.dscalar.nii"))
expand = lambda values, where: np.where(np.isin(np.arange(12), where), values, np.nan)  # noqa: E731
csv("expected_cifti_left_thickness.csv", "thickness", expand(thickness, left))
csv("expected_cifti_left_myelin.csv", "myelin", expand(myelin, left))
csv("expected_cifti_right_myelin.csv", "myelin", expand(myelin + np.float32(1), right))

# CIFTI-2 dense labels (.dlabel.nii) on the same brain models' surfaces: two
# maps, each with its own label table (key 0 "???" as Workbench writes it);
# the keys are stored as float32, as HCP's files store them.
parcels_table = {0: ("???", (0.0, 0.0, 0.0, 0.0)), 4: ("precentral", (0.8, 0.1, 0.05, 1.0)),
                 7: ("postcentral", (0.1, 0.8, 0.25, 1.0)), 9: ("insula", (1.0, 0.75, 0.125, 1.0))}
halves_table = {0: ("???", (0.0, 0.0, 0.0, 0.0)), 1: ("front", (0.5, 0.25, 1.0, 1.0)),
                2: ("back", (0.25, 1.0, 0.5, 1.0))}
halves = np.where(points[:, 1] > points[:, 1].mean(), 1, 2).astype(np.int32)
surface_brain = (ax.BrainModelAxis.from_surface(left, 12, "CortexLeft")
                 + ax.BrainModelAxis.from_surface(right, 12, "CortexRight"))
right_keys = gifti_keys[::-1]
labels = np.vstack([
    np.concatenate([gifti_keys[left], right_keys[right]]),
    np.concatenate([halves[left], halves[right]]),
]).astype(np.float32)
dlabel = nib.Cifti2Image(labels, header=(ax.LabelAxis(["parcels", "halves"], [parcels_table, halves_table]),
                                         surface_brain))
dlabel.nifti_header.set_intent("ConnDenseLabel")
dlabel.to_filename(os.path.join(out, "parcels.dlabel.nii"))
off = lambda keys, where: np.where(np.isin(np.arange(12), where), keys, 0)  # noqa: E731
csv("expected_dlabel_left_parcels.csv", "key", off(gifti_keys, left))
csv("expected_dlabel_right_halves.csv", "key", off(halves, right))

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
    elif name == "parcels.label.gii":
        g = nib.load(path)
        assert np.array_equal(g.darrays[0].data, gifti_keys), name
        assert g.labeltable.get_labels_as_dict()[7] == "postcentral", name
    elif name.endswith(".gii"):
        assert np_equal(nib.load(path).darrays[0].data, thickness), name
    elif name == "lh.icosahedron":
        p, f = nib.freesurfer.read_geometry(path)
        assert np_equal(p, points) and np_equal(f, faces), name
    elif name == "lh.thickness":
        assert np_equal(nib.freesurfer.read_morph_data(path), thickness), name
    elif name == "lh.parcels.annot":
        keys, table, read_names = nib.freesurfer.read_annot(path)
        assert np.array_equal(keys, parcel) and [n.decode() for n in read_names] == names, name
    elif name == "maps.dscalar.nii":
        img = nib.load(path)
        assert np.array_equal(img.get_fdata(dtype=np.float32), maps), name
    elif name == "parcels.dlabel.nii":
        img = nib.load(path)
        assert np.array_equal(img.get_fdata(dtype=np.float32), labels), name
        label_axis = img.header.get_axis(0)
        assert label_axis.label[1][2] == ("back", (0.25, 1.0, 0.5, 1.0)), name
    elif name.startswith("thickness.mg"):
        assert np_equal(np.asarray(nib.load(path).dataobj).ravel(), thickness), name
print(f"wrote {len(os.listdir(out))} files to {out} with nibabel {nib.__version__}")
