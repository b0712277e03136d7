//! Generators: icospheres, Delaunay squares, polygonal circles, image grids,
//! and images sampled onto vertices.

use std::collections::HashMap;

use spade::{AngleLimit, ConstrainedDelaunayTriangulation, Point2, RefinementParameters, Triangulation};

use crate::io::image::Image;
use crate::shape::{CellKind, FShape};

/// A deterministic pseudo-random generator (SplitMix64). Written here
/// because the generators and test helpers only need reproducible uniform
/// numbers, identical on every platform and release, which a 10-line
/// generator guarantees without a dependency.
#[derive(Clone, Debug)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A uniform number in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A uniform number in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// A standard normal number (Box–Muller, from two uniform numbers).
    pub fn normal(&mut self) -> f64 {
        let (u, v) = (1.0 - self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// The icosphere of the given subdivision level and radius, centred at the
/// origin: the icosahedron with each triangle split in four `level` times,
/// new vertices pushed to the sphere. It has 10·4^level + 2 vertices
/// (level 5: 10242, the paper's template) and 20·4^level triangles, all
/// oriented with outward normals.
///
/// ```
/// let s = fshape_mesh::generate::icosphere(1, 1.0);
/// assert_eq!((s.n_vertices(), s.n_cells()), (42, 80));
/// ```
pub fn icosphere(level: u32, radius: f64) -> FShape {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut pts: Vec<[f64; 3]> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .iter()
    .map(|p| normalise(*p))
    .collect();
    let mut tris: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut mid: HashMap<(usize, usize), usize> = HashMap::new();
        let mut next = Vec::with_capacity(tris.len() * 4);
        for [a, b, c] in tris {
            let mut m = |i: usize, j: usize| {
                *mid.entry((i.min(j), i.max(j))).or_insert_with(|| {
                    let (p, q) = (pts[i], pts[j]);
                    pts.push(normalise([p[0] + q[0], p[1] + q[1], p[2] + q[2]]));
                    pts.len() - 1
                })
            };
            let (ab, bc, ca) = (m(a, b), m(b, c), m(c, a));
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    let points = pts.iter().flat_map(|p| p.map(|x| x * radius)).collect();
    let cells = tris.iter().flatten().copied().collect();
    FShape::try_new(3, CellKind::Triangle, points, cells, None).expect("the icosphere is a valid shape")
}

fn normalise(p: [f64; 3]) -> [f64; 3] {
    let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    [p[0] / n, p[1] / n, p[2] / n]
}

/// A Delaunay triangulation of the square [-1, 1]² with about `target`
/// vertices and no angle below 30° (spade's Ruppert refinement), triangles
/// counter-clockwise. `seed = 0` starts from the boundary alone; another
/// seed adds `target / 8` random interior points first, which gives a
/// different triangulation of similar size and quality (the paper matches
/// digits on two different triangulations).
///
/// ```
/// let s = fshape_mesh::generate::square(500, 0);
/// assert!((s.total_volume() - 4.0).abs() < 1e-12);
/// ```
pub fn square(target: usize, seed: u64) -> FShape {
    let target = target.max(4);
    // Boundary points at about the interior spacing, so refinement does not
    // have to split the boundary much: ~sqrt(target) per side.
    let per_side = ((target as f64).sqrt().round() as usize).max(1);
    let mut verts = Vec::new();
    for k in 0..per_side {
        let s = -1.0 + 2.0 * k as f64 / per_side as f64;
        verts.extend([Point2::new(s, -1.0), Point2::new(1.0, s), Point2::new(-s, 1.0), Point2::new(-1.0, -s)]);
    }
    let n_b = verts.len();
    let mut rng = SplitMix64(seed);
    if seed != 0 {
        for _ in 0..target / 8 {
            verts.push(Point2::new(rng.range(-0.98, 0.98), rng.range(-0.98, 0.98)));
        }
    }
    // The boundary points were made side by side, interleaved; the square is
    // star-shaped about the origin, so angular order is boundary order.
    let mut order: Vec<usize> = (0..n_b).collect();
    order.sort_by(|&i, &j| angle(verts[i]).total_cmp(&angle(verts[j])));
    let edges: Vec<[usize; 2]> = (0..n_b).map(|k| [order[k], order[(k + 1) % n_b]]).collect();
    let mut cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::bulk_load_cdt(verts, edges)
        .expect("square boundary constraints do not intersect");
    // Mean triangle area of a quality mesh is ~0.6 of the cap; 2N triangles
    // cover an area of 4.
    let max_area = 4.0 / (2.0 * target as f64) / 0.6;
    cdt.refine(
        RefinementParameters::<f64>::new()
            .with_angle_limit(AngleLimit::from_deg(30.0))
            .with_max_allowed_area(max_area)
            .with_max_additional_vertices(20 * target + 1000),
    );
    let points = cdt.vertices().flat_map(|v| [v.position().x, v.position().y]).collect();
    let cells = cdt.inner_faces().flat_map(|f| f.vertices().map(|v| v.fix().index())).collect();
    FShape::try_new(2, CellKind::Triangle, points, cells, None).expect("spade returns a valid triangulation")
}

fn angle(p: Point2<f64>) -> f64 {
    p.y.atan2(p.x)
}

/// A closed polygon of `n` segments on the circle of the given radius in
/// the plane, counter-clockwise.
///
/// ```
/// let c = fshape_mesh::generate::circle(6, 1.0);
/// assert!((c.total_volume() - 6.0).abs() < 1e-12); // a regular hexagon
/// ```
pub fn circle(n: usize, radius: f64) -> FShape {
    let n = n.max(3);
    let points = (0..n)
        .flat_map(|k| {
            let a = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
            [radius * a.cos(), radius * a.sin()]
        })
        .collect();
    let cells = (0..n).flat_map(|k| [k, (k + 1) % n]).collect();
    FShape::try_new(2, CellKind::Segment, points, cells, None).expect("a circle is a valid shape")
}

/// A polygonal curve through `points` (`dim` coordinates each), closed
/// when `closed`.
pub fn polyline(dim: usize, points: Vec<f64>, closed: bool) -> Result<FShape, crate::ShapeError> {
    let n = points.len() / dim.max(1);
    let mut cells: Vec<usize> = (0..n.saturating_sub(1)).flat_map(|k| [k, k + 1]).collect();
    if closed && n > 2 {
        cells.extend([n - 1, 0]);
    }
    FShape::try_new(dim, CellKind::Segment, points, cells, None)
}

/// The image as a flat fshape: one vertex per pixel centre on [-1, 1]²
/// (see [`Image::pixel_centre`]) carrying the pixel value, two
/// counter-clockwise triangles per square of four neighbouring centres.
/// Fails (naming the pixel as a vertex) if a value is not finite.
pub fn image_grid(image: &Image) -> Result<FShape, crate::ShapeError> {
    let (w, h) = (image.width, image.height);
    let points = (0..h).flat_map(|r| (0..w).flat_map(move |c| [c, r])).collect::<Vec<_>>();
    let points = points
        .chunks_exact(2)
        .flat_map(|cr| {
            let (x, y) = image.pixel_centre(cr[0], cr[1]);
            [x, y]
        })
        .collect();
    let id = |c: usize, r: usize| r * w + c;
    let mut cells = Vec::new();
    for r in 0..h.saturating_sub(1) {
        for c in 0..w.saturating_sub(1) {
            // Rows go down in y, so (c,r) → (c,r+1) → (c+1,r+1) is counter-clockwise.
            cells.extend([id(c, r), id(c, r + 1), id(c + 1, r + 1), id(c, r), id(c + 1, r + 1), id(c + 1, r)]);
        }
    }
    FShape::try_new(2, CellKind::Triangle, points, cells, Some(image.values.clone()))
}

/// The image sampled at every vertex of a planar shape by bilinear
/// interpolation (see [`Image::sample`]), e.g. a digit on a Delaunay square.
///
/// # Panics
/// If the shape is not planar (`dim() != 2`).
#[track_caller]
pub fn sample_image(image: &Image, shape: &FShape) -> Vec<f64> {
    assert_eq!(shape.dim(), 2, "images are sampled onto planar shapes");
    shape.points().chunks_exact(2).map(|p| image.sample(p[0], p[1])).collect()
}
