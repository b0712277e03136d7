//! Every shipped data file reads with the counts stated in data/README.md,
//! which come from the data set's own numpy/trimesh checks, not from fshape.

use fshape_mesh::io::{ReadOptions, csv, image, read_mesh};
use fshape_mesh::{FShape, Repairs};

use crate::data;

fn read(rel: &str) -> FShape {
    read_mesh(&data(rel), &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

/// (file, vertices, cells, boundary loops, unused vertices, duplicate cells,
/// non-manifold edges, repeated half-edges), from data/README.md.
type Counts = (usize, usize, usize, usize, usize, usize, usize);

const COUNTS: &[(&str, Counts)] = &[
    ("fsaverage5/lh.pial.thick.ply.gz", (10242, 20480, 0, 0, 0, 0, 0)),
    ("fsaverage5/rh.pial.ply.gz", (10242, 20480, 0, 0, 0, 0, 0)),
    ("stanford_bunny/bun_zipper.ply.gz", (35947, 69451, 5, 1113, 0, 0, 0)),
    ("stanford_bunny/bun_zipper_res2.ply.gz", (8171, 16301, 5, 25, 87, 150, 298)),
    ("stanford_bunny/bun_zipper_res3.ply.gz", (1889, 3851, 4, 2, 83, 141, 281)),
    ("stanford_bunny/bun_zipper_res4.ply.gz", (453, 948, 4, 0, 40, 70, 138)),
    ("stanford_bunny/bunny_qslim_2581v.ply.gz", (2581, 5138, 4, 0, 0, 0, 0)),
    ("stanford_bunny/stanford-bunny.obj.gz", (35947, 69451, 5, 1113, 0, 0, 0)),
    ("pycortex_S1/lh.pia.ply.gz", (152893, 305782, 0, 0, 0, 0, 0)),
    ("conte69_32k/lh.midthickness.ply.gz", (32492, 64980, 0, 0, 0, 0, 0)),
];

#[test]
fn shipped_meshes_have_the_stated_counts() {
    for &(file, expect) in COUNTS {
        let s = read(file);
        let topo = s.topology();
        let report = s.validate();
        let got = (
            s.n_vertices(),
            s.n_cells(),
            topo.n_boundary_loops,
            report.count("unused_vertex"),
            report.count("duplicate_cell"),
            report.count("non_manifold_facet"),
            report.count("inconsistent_orientation"),
        );
        assert_eq!(got, expect, "{file}");
        assert_eq!(report.errors().count(), 0, "{file}: {report}");
        assert_eq!(topo.n_components, 1, "{file}");
    }
}

#[test]
fn duplicate_orientation_split_matches_the_reference() {
    // data/README.md: res2 6 same + 81 opposite, res3 14 + 69, res4 9 + 31.
    for (file, same, opposite) in [
        ("stanford_bunny/bun_zipper_res2.ply.gz", 6, 81),
        ("stanford_bunny/bun_zipper_res3.ply.gz", 14, 69),
        ("stanford_bunny/bun_zipper_res4.ply.gz", 9, 31),
    ] {
        let report = read(file).validate();
        let split = report.problems.iter().fold((0, 0), |(s, o), p| match p {
            fshape_mesh::Finding::DuplicateCell { same_orientation: true, .. } => (s + 1, o),
            fshape_mesh::Finding::DuplicateCell { .. } => (s, o + 1),
            _ => (s, o),
        });
        assert_eq!(split, (same, opposite), "{file}");
    }
}

#[test]
fn dropping_duplicates_of_dirty_bunnies_matches_the_reference() {
    // checks.json "after_removing_duplicate_faces": (faces, boundary edges,
    // boundary loops, non-manifold edges, repeated half-edges, Euler χ).
    let only_dups = Repairs { drop_unused_vertices: false, drop_zero_volume_cells: false, drop_duplicate_cells: true };
    for (file, expect) in [
        ("stanford_bunny/bun_zipper_res2.ply.gz", (16214, 215, 70, 125, 139, -3)),
        ("stanford_bunny/bun_zipper_res3.ply.gz", (3768, 125, 54, 103, 115, -6)),
        ("stanford_bunny/bun_zipper_res4.ply.gz", (908, 55, 22, 47, 60, -2)),
    ] {
        let (s, _) = read(file).repaired(only_dups);
        let t = s.topology();
        let got = (
            s.n_cells(),
            t.boundary_facets.len(),
            t.n_boundary_loops,
            t.nonmanifold_facets.len(),
            t.misoriented_facets.len(),
            t.euler_characteristic(s.kind(), s.n_cells()),
        );
        assert_eq!(got, expect, "{file}");
    }
}

#[test]
fn cortex_is_a_closed_outward_sphere_with_thickness() {
    let s = read("fsaverage5/lh.pial.thick.ply.gz");
    let t = s.topology();
    assert!(t.is_closed());
    assert_eq!(t.euler_characteristic(s.kind(), s.n_cells()), 2);
    // checks.json: total area 76345.44437523794 mm², signed volume 500035.59 mm³.
    assert!((s.total_volume() / 76345.44437523794 - 1.0).abs() < 1e-9);
    assert!((s.signed_enclosed_volume().unwrap() / 500035.5907430509 - 1.0).abs() < 1e-9);
    let f = s.signal().expect("the `signal` property is read by default");
    let (lo, hi) = f.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    // data/README.md: thickness −0.003 to 4.66 mm, mean 2.27.
    assert!((-0.0029..-0.0027).contains(&lo), "{lo}");
    assert!((4.65..4.66).contains(&hi), "{hi}");
    let mean = f.iter().sum::<f64>() / f.len() as f64;
    assert!((mean - 2.27).abs() < 0.005, "{mean}");
    // The CSV copy of the same thickness agrees with the PLY property.
    let col = csv::read_signal(&data("fsaverage5/lh.thick.csv.gz"), false).unwrap();
    assert_eq!(col.values.len(), 10242);
    assert!(col.values.iter().zip(f).all(|(a, b)| (a - b).abs() <= 1e-6 * b.abs().max(1.0)));
}

#[test]
fn scanner_fields_are_never_the_signal() {
    // bun_zipper has `confidence` and `intensity`, and no `signal`.
    let s = read("stanford_bunny/bun_zipper.ply.gz");
    assert!(s.signal().is_none());
    let named =
        read_mesh(&data("stanford_bunny/bun_zipper.ply.gz"), &ReadOptions { signal_name: Some("confidence".into()) })
            .unwrap();
    assert_eq!(named.signal().unwrap()[0], 0.850855); // first vertex line of the file
    let err =
        read_mesh(&data("stanford_bunny/bun_zipper.ply.gz"), &ReadOptions { signal_name: Some("thickness".into()) })
            .unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("bun_zipper.ply.gz") && msg.contains("`thickness`") && msg.contains("confidence, intensity"),
        "{msg}"
    );
}

#[test]
fn obj_bunny_matches_ply_bunny_and_tobj() {
    let ply = read("stanford_bunny/bun_zipper.ply.gz");
    let obj = read("stanford_bunny/stanford-bunny.obj.gz");
    assert_eq!(ply.cells(), obj.cells(), "same faces in the same order");
    // data/README.md: vertices differ by at most 5e-7 (MeshLab's rounding to
    // 6 decimals); 1e-15 more for the binary representation of both values.
    let dmax = ply.points().iter().zip(obj.points()).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(dmax <= 5e-7 + 1e-15, "{dmax}");
    // tobj, an independent reader, renumbers vertices but keeps face order:
    // compare the corners' coordinates face by face.
    let bytes = fshape_mesh::io::read_bytes(&data("stanford_bunny/stanford-bunny.obj.gz")).unwrap();
    let (models, _) =
        tobj::load_obj_buf(&mut &bytes[..], &tobj::LoadOptions { triangulate: true, ..Default::default() }, |_| {
            Err(tobj::LoadError::OpenFileFailed)
        })
        .unwrap();
    let m = &models[0].mesh;
    assert_eq!(m.indices.len(), 3 * obj.n_cells());
    for (k, &i) in m.indices.iter().enumerate() {
        let ours = obj.point(obj.cells()[k]);
        let theirs = &m.positions[3 * i as usize..3 * i as usize + 3];
        assert_eq!(ours, theirs, "corner {k}");
    }
}

#[test]
fn digits_are_28_by_28_grey_images() {
    for name in ["mnist5k_1000_label2.csv", "mnist5k_1498_label2.csv", "mnist5k_2500_label5.csv"] {
        let im = image::read_image(&data(&format!("digits/{name}")), None).unwrap();
        assert_eq!((im.width, im.height), (28, 28), "{name}");
        assert!(im.values.iter().all(|&v| (0.0..=255.0).contains(&v) && v.fract() == 0.0));
        assert!(im.values.iter().any(|&v| v > 200.0), "a digit has ink");
    }
}
