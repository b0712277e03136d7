//! Validation on hand-made shapes: each problem found, with its index.

use fshape_mesh::{CellKind, FShape, Finding, Repairs, Severity, ShapeError};

/// Two triangles sharing the edge (1, 2), consistently oriented.
fn square_pts() -> Vec<f64> {
    vec![0., 0., 1., 0., 1., 1., 0., 1.]
}

#[test]
fn every_blocking_problem_is_reported_at_once() {
    let mut pts = square_pts();
    pts[3] = f64::NAN; // vertex 1
    let err = FShape::try_new(
        2,
        CellKind::Triangle,
        pts,
        vec![0, 1, 2, 0, 2, 9, 3, 3, 1],
        Some(vec![0.0, f64::INFINITY, 0.0]),
    )
    .unwrap_err();
    let ShapeError::Invalid { problems } = &err else { panic!("{err}") };
    assert_eq!(
        problems,
        &vec![
            Finding::NonFiniteCoordinate { vertex: 1 },
            Finding::SignalLength { expected: 4, found: 3 },
            Finding::NonFiniteSignal { vertex: 1 },
            Finding::IndexOutOfRange { cell: 1, index: 9, n_vertices: 4 },
            Finding::RepeatedIndex { cell: 2, vertex: 3 },
        ]
    );
    assert!(problems.iter().all(|p| p.severity() == Severity::Error));
    let msg = err.to_string();
    assert!(msg.contains("cell 1 uses vertex 9, but there are only 4 vertices"), "{msg}");
    assert!(msg.contains("vertex 1 has a NaN or infinite coordinate"), "{msg}");
}

#[test]
fn structural_mismatches_are_errors() {
    assert_eq!(
        FShape::try_new(4, CellKind::Triangle, vec![], vec![], None).unwrap_err(),
        ShapeError::Dimension { dim: 4 }
    );
    assert!(matches!(
        FShape::try_new(3, CellKind::Triangle, vec![0.0; 4], vec![], None),
        Err(ShapeError::PointsLength { len: 4, dim: 3 })
    ));
    assert!(matches!(
        FShape::try_new(2, CellKind::Triangle, vec![0.0; 6], vec![0, 1], None),
        Err(ShapeError::CellsLength { .. })
    ));
}

#[test]
fn warnings_name_their_cells_and_vertices() {
    // Vertex 4 unused; cell 2 repeats cell 0 reversed; cell 3 is flat
    // (collinear 0, 1, 5); cell 1 traverses 0→2 like cell 4 does.
    let pts = vec![0., 0., 1., 0., 1., 1., 0., 1., 5., 5., 2., 0.];
    let cells = vec![0, 1, 2, 0, 2, 3, 2, 1, 0, 0, 1, 5, 0, 2, 3];
    let s = FShape::try_new(2, CellKind::Triangle, pts, cells, None).unwrap();
    let r = s.validate();
    assert_eq!(r.errors().count(), 0);
    assert!(r.problems.contains(&Finding::UnusedVertex { vertex: 4 }));
    assert!(r.problems.contains(&Finding::DuplicateCell { cell: 2, first: 0, same_orientation: false }));
    assert!(r.problems.contains(&Finding::DuplicateCell { cell: 4, first: 1, same_orientation: true }));
    assert!(r.problems.contains(&Finding::ZeroVolumeCell { cell: 3, volume: 0.0 }));
    // Edge (0, 1) is in cells 0, 2 and 3: non-manifold.
    assert!(r.problems.contains(&Finding::NonManifoldFacet { facet: [0, 1], cells: 3 }));
    // Cells 1 and 4 both traverse 2→3.
    assert!(r.problems.contains(&Finding::InconsistentOrientation { facet: [2, 3] }));
    assert!(r.warnings().all(|p| p.severity() == Severity::Warning));

    let (fixed, log) = s.repaired(Repairs::ALL);
    assert_eq!(log.dropped_cells, vec![2, 3, 4]);
    assert_eq!(log.dropped_vertices, vec![4, 5]);
    assert_eq!(log.vertex_map, vec![Some(0), Some(1), Some(2), Some(3), None, None]);
    assert_eq!(fixed.cells(), &[0, 1, 2, 0, 2, 3]);
    let left: Vec<&str> = fixed.validate().problems.iter().map(Finding::code).collect();
    assert_eq!(left, vec!["boundary"], "only the boundary of the unit square remains");
}

#[test]
fn curve_topology() {
    // A "Y": vertex 0 has three segments; segments 0 and 1 both start at 0.
    let s = FShape::try_new(2, CellKind::Segment, vec![0., 0., 1., 0., 0., 1., -1., -1.], vec![0, 1, 0, 2, 3, 0], None)
        .unwrap();
    let t = s.topology();
    assert_eq!(t.nonmanifold_facets, vec![([0, 0], 3)]);
    assert_eq!(t.misoriented_facets, vec![[0, 0]]);
    assert_eq!(t.n_boundary_loops, 3, "three free end points");
}

#[test]
fn a_mask_allows_missing_values_where_it_is_zero_and_nowhere_else() {
    let s = fshape_mesh::generate::icosphere(1, 1.0);
    let n = s.n_vertices();
    let mut m = vec![1.0; n];
    m[3] = 0.0;
    m[4] = 0.5;
    let mut f = vec![2.0; n];
    f[3] = f64::NAN;
    let a = s.clone().with_signal_and_mask(Some(f.clone()), Some(m.clone())).unwrap();
    assert!(a.signal().unwrap()[3].is_nan() && a.mask().unwrap()[4] == 0.5);
    // Whatever was given at a masked vertex, it is stored as NaN: the same shape.
    f[3] = 1e300;
    let b = s.clone().with_signal_and_mask(Some(f.clone()), Some(m.clone())).unwrap();
    assert_eq!(a, b);
    assert!(b.signal().unwrap()[3].is_nan());
    // NaN where the mask is positive, a mask outside [0, 1] or of the wrong length: refused, with the vertex.
    f[4] = f64::NAN;
    let e = s.clone().with_signal_and_mask(Some(f), Some(m.clone())).unwrap_err().to_string();
    assert!(e.contains("vertex 4"), "{e}");
    let mut bad = m.clone();
    bad[7] = 1.5;
    let e = s.clone().with_mask(Some(bad)).unwrap_err().to_string();
    assert!(e.contains("vertex 7 has the mask value 1.5"), "{e}");
    let e = s.clone().with_mask(Some(vec![1.0; n - 1])).unwrap_err().to_string();
    assert!(e.contains(&format!("the mask has {} values for {n} vertices", n - 1)), "{e}");
    // The mask moves with the points and stays with a new signal.
    let moved = a.clone().with_points(a.points().iter().map(|x| 2.0 * x).collect()).unwrap();
    assert_eq!(moved.mask(), a.mask());
    assert_eq!(moved.with_signal(Some(vec![0.0; n])).unwrap().mask(), Some(&m[..]));
}

#[test]
fn several_channels_are_checked_masked_and_carried_vertex_by_vertex() {
    let s = fshape_mesh::generate::icosphere(2, 1.0);
    let n = s.n_vertices();
    // Channel c of vertex v is 10 v + c.
    let f: Vec<f64> = (0..n).flat_map(|v| (0..3).map(move |c| (10 * v + c) as f64)).collect();
    let a = s.clone().with_signals(Some(f.clone()), 3).unwrap();
    assert_eq!((a.n_channels(), a.channel(2).unwrap()[5], a.channel(3)), (3, 52.0, None));
    assert_eq!(s.n_channels(), 0);
    // The length is checked against vertices × channels; a missing value
    // is named by its vertex.
    let e = s.clone().with_signals(Some(f[..3 * n - 1].to_vec()), 3).unwrap_err();
    let ShapeError::Invalid { problems } = &e else { panic!("{e}") };
    assert_eq!(problems, &vec![Finding::SignalLength { expected: 3 * n, found: 3 * n - 1 }]);
    let mut g = f.clone();
    g[3 * 7 + 1] = f64::NAN;
    let e = s.clone().with_signals(Some(g.clone()), 3).unwrap_err();
    assert!(e.to_string().contains("vertex 7"), "{e}");
    assert!(matches!(s.clone().with_signals(Some(vec![]), 0), Err(ShapeError::Channels)));
    // A mask masks every channel of a vertex, and only there.
    let mut m = vec![1.0; n];
    m[7] = 0.0;
    let b = s.clone().with_signals_and_mask(Some(g), 3, Some(m.clone())).unwrap();
    assert!(b.signal().unwrap()[21..24].iter().all(|v| v.is_nan()));
    assert_eq!(b.signal().unwrap()[24..27], [80.0, 81.0, 82.0]);
    // Simplification keeps whole rows; a one-channel shape is not a
    // three-channel one.
    let c = b.simplified(n / 3).unwrap();
    for (i, &v) in c.kept.iter().enumerate() {
        let row = &c.shape.signal().unwrap()[3 * i..3 * i + 3];
        if v == 7 {
            assert!(row.iter().all(|x| x.is_nan()));
        } else {
            assert_eq!(row, &f[3 * v..3 * v + 3]);
        }
    }
    assert_eq!((c.shape.n_channels(), c.shape.mask().map(<[f64]>::len)), (3, Some(c.kept.len())));
    // Dropping an unused vertex keeps the others' rows and mask weights.
    let mut pts = square_pts();
    pts.extend([5.0, 5.0]);
    let sq = FShape::try_new(2, CellKind::Triangle, pts, vec![0, 1, 2, 0, 2, 3], None).unwrap();
    let rows: Vec<f64> = (0..5).flat_map(|v| [v as f64, -(v as f64)]).collect();
    let sq = sq.with_signals_and_mask(Some(rows.clone()), 2, Some(vec![1.0, 0.0, 1.0, 0.5, 1.0])).unwrap();
    let repairs = Repairs { drop_unused_vertices: true, drop_zero_volume_cells: false, drop_duplicate_cells: false };
    let (r, _) = sq.repaired(repairs);
    assert_eq!((r.n_vertices(), r.n_channels(), r.mask()), (4, 2, Some(&[1.0, 0.0, 1.0, 0.5][..])));
    assert_eq!(r.channel(1).unwrap()[3], -3.0);
    // Mesh files carry a property or array per channel (signal,
    // signal_2, …) and read them back as channels, masked or not; a reader
    // that knows one signal reads the first channel, and any channel is
    // read alone by its name.
    use fshape_mesh::io::{Encoding, Format, ReadOptions, parse_mesh, write_to};
    let path = std::path::Path::new("channels");
    for (shape, what) in [(&a, "plain"), (&b, "masked")] {
        for format in [Format::Ply, Format::Vtk, Format::Gifti] {
            for encoding in [Encoding::Ascii, Encoding::Binary] {
                let mut bytes = Vec::new();
                write_to(&mut bytes, shape, format, encoding).unwrap();
                let back = parse_mesh(&bytes, format, &ReadOptions::default(), path).unwrap();
                let label = format!("{what} {format:?} {encoding:?}");
                assert_eq!(back.n_channels(), 3, "{label}");
                assert_eq!(back.mask(), shape.mask(), "{label}");
                for c in 0..3 {
                    let (got, want) = (back.channel(c).unwrap(), shape.channel(c).unwrap());
                    assert!(
                        got.iter().zip(&want).all(|(x, y)| x == y || x.is_nan() && y.is_nan()),
                        "{label}: channel {c}"
                    );
                }
                let opts = ReadOptions { signal_name: Some("signal_3".into()) };
                let third = parse_mesh(&bytes, format, &opts, path).unwrap();
                assert_eq!(third.n_channels(), 1, "{label}");
                let (got, want) = (third.signal().unwrap(), shape.channel(2).unwrap());
                assert!(got.iter().zip(&want).all(|(x, y)| x == y || x.is_nan() && y.is_nan()), "{label}");
            }
        }
    }
}
