//! The conservation law (paper Theorem conservation_law): along an optimal
//! trajectory of a reparametrisation-invariant data term, the momentum map
//! μ_t = dq_tᵀ p_t + df_tᵀ p^f vanishes: ⟨p_t, u⟩ + p^f·(∇f_t·u) = 0 for
//! every tangent field u. Optimal trajectories without an optimiser: at
//! t = 1 the optimality conditions give p_1 = −γ_W ∂_x A(X_1, Y) and
//! p^f = −γ_W ∂_f A(X_1, Y); shooting backward from there yields the
//! optimal trajectory ending at X_1.

use fshape_kernels::Kernel;
use fshape_mesh::FShape;
use fshape_mesh::generate::icosphere;
use fshape_mesh::test_support::observed_order;
use fshape_shoot::Problem;
use fshape_varifold::{Attachment, GrassKernel, SignalKernel, VarifoldKernel};

use crate::model;

fn f(p: &[f64]) -> f64 {
    (2.0 * p[0]).sin() + p[1] * p[2]
}

/// Per-vertex gradient of the P1 interpolant of `f` on a triangle mesh:
/// the area-weighted mean of the (tangent) gradients of its triangles.
fn vertex_gradients(s: &FShape, f: &[f64]) -> Vec<[f64; 3]> {
    let mut g = vec![[0.0; 3]; s.n_vertices()];
    let mut w = vec![0.0; s.n_vertices()];
    for c in s.cell_iter() {
        let p = |k: usize| -> [f64; 3] { s.point(c[k]).try_into().unwrap() };
        let (a, b, d) = (p(0), p(1), p(2));
        let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let e2 = [d[0] - a[0], d[1] - a[1], d[2] - a[2]];
        let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
        let nn = n.iter().map(|v| v * v).sum::<f64>();
        let area = 0.5 * nn.sqrt();
        let (df1, df2) = (f[c[1]] - f[c[0]], f[c[2]] - f[c[0]]);
        let cross = |u: [f64; 3], v: [f64; 3]| {
            [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
        };
        // ∇f = (df1 (e2 × n) + df2 (n × e1)) / |n|², the unique tangent vector
        // with ∇f·e1 = df1 and ∇f·e2 = df2.
        let (a1, a2) = (cross(e2, n), cross(n, e1));
        let grad: [f64; 3] = std::array::from_fn(|k| (df1 * a1[k] + df2 * a2[k]) / nn);
        for &v in c {
            for k in 0..3 {
                g[v][k] += area * grad[k];
            }
            w[v] += area;
        }
    }
    g.iter().zip(&w).map(|(v, a)| v.map(|x| x / a)).collect()
}

/// Outward unit vertex normals (area-weighted).
fn vertex_normals(s: &FShape) -> Vec<[f64; 3]> {
    let mut nrm = vec![[0.0; 3]; s.n_vertices()];
    for (t, c) in s.cell_iter().enumerate() {
        let n = s.cell_vector(t);
        for &v in c {
            for k in 0..3 {
                nrm[v][k] += n[k];
            }
        }
    }
    nrm.iter()
        .map(|n| {
            let l = n.iter().map(|v| v * v).sum::<f64>().sqrt();
            n.map(|x| x / l)
        })
        .collect()
}

/// An optimal trajectory ending at X_1 (an icosphere of `level` carrying
/// f), built by shooting backward from the optimality conditions.
struct Optimal {
    x1: FShape,
    traj: fshape_shoot::Trajectory,
    pf: Vec<f64>,
}

fn optimal(level: u32) -> Optimal {
    let sphere = icosphere(level, 1.0);
    let sig: Vec<f64> = sphere.points().chunks_exact(3).map(f).collect();
    let x1 = sphere.with_signal(Some(sig)).unwrap();
    let target = {
        let s = icosphere(4, 1.0);
        let pts: Vec<f64> = s.points().chunks_exact(3).flat_map(|p| [1.2 * p[0], p[1], 0.85 * p[2]]).collect();
        let sig: Vec<f64> = pts.chunks_exact(3).map(|p| (p[0] + p[1]).cos()).collect();
        s.with_points(pts).unwrap().with_signal(Some(sig)).unwrap()
    };
    let k = VarifoldKernel::try_new(
        Kernel::gaussian(0.5).unwrap(),
        SignalKernel::Gaussian { sigma: 0.5 },
        GrassKernel::UnorientedGaussian { sigma: 0.7 },
    )
    .unwrap();
    let gamma_w = 1.0;
    let (_, g) = Attachment::new(&target, k).unwrap().eval_grad(&x1).unwrap();
    // p_1 = −γ_W ∂_x A, p^f = −γ_W ∂_f A; backward in time = forward from
    // X_1 with the momenta negated.
    let back_p: Vec<f64> = g.points.iter().map(|v| gamma_w * v).collect();
    let back_pf: Vec<f64> = g.signal.iter().map(|v| gamma_w * v).collect();
    let m = model(0.4, "h1", 0.3, 1.0, 0.5, "rk4", 10);
    let traj = Problem::new(&x1, m).unwrap().shoot(&back_p, &back_pf).unwrap();
    let pf: Vec<f64> = g.signal.iter().map(|v| -gamma_w * v).collect();
    Optimal { x1, traj, pf }
}

/// The trajectories for levels 3, 4, 5, built once for every test here.
fn optimals() -> &'static [Optimal] {
    static CACHE: std::sync::OnceLock<Vec<Optimal>> = std::sync::OnceLock::new();
    CACHE.get_or_init(|| (3..=5).map(optimal).collect())
}

/// The smooth ambient field w(p) = (c₀ sin 2y + c₁, c₂ cos z + c₃ x, c₄ xy + c₅ z²).
fn field(c: &[f64; 6], p: &[f64]) -> [f64; 3] {
    [c[0] * (2.0 * p[1]).sin() + c[1], c[2] * p[2].cos() + c[3] * p[0], c[4] * p[0] * p[1] + c[5] * p[2] * p[2]]
}

/// max over every step t of |⟨p_t,u⟩ + ⟨p^f, ∇f_t·u⟩| / (Σ|p_k||u_k| +
/// Σ|p^f_k||∇f_t·u|_k), u = w projected on the tangent planes; and the
/// pointwise tangential residual Σ|p_tan + p^f ∇f_t| / Σ(|p_tan| + |p^f ∇f_t|).
fn residual(o: &Optimal, c: &[f64; 6]) -> (f64, f64) {
    let (x1, traj, pf) = (&o.x1, &o.traj, &o.pf);
    let (mut worst, mut worst_tan): (f64, f64) = (0.0, 0.0);
    for step in 0..=traj.steps() {
        let xt = x1.clone().with_points(traj.points(step).to_vec()).unwrap();
        let ft = traj.signal(step);
        let pt: Vec<f64> = traj.momenta(step).iter().map(|v| -v).collect();
        let (grads, normals) = (vertex_gradients(&xt, ft), vertex_normals(&xt));
        let (mut sum, mut size) = (0.0, 0.0);
        // The same law for every tangent u at once: the tangential part of
        // p_t equals −p^f ∇f_t (p_t is normal where f is locally constant).
        let (mut tan_num, mut tan_den) = (0.0, 0.0);
        for (v, p) in xt.points().chunks_exact(3).enumerate() {
            let pv = &pt[3 * v..3 * v + 3];
            let pn: f64 = (0..3).map(|i| pv[i] * normals[v][i]).sum();
            let ptan: Vec<f64> = (0..3).map(|i| pv[i] - pn * normals[v][i]).collect();
            let gn: f64 = (0..3).map(|i| grads[v][i] * normals[v][i]).sum();
            let gtan: Vec<f64> = (0..3).map(|i| pf[v] * (grads[v][i] - gn * normals[v][i])).collect();
            let len = |a: &[f64]| a.iter().map(|t| t * t).sum::<f64>().sqrt();
            let diff: Vec<f64> = (0..3).map(|i| ptan[i] + gtan[i]).collect();
            tan_num += len(&diff);
            tan_den += len(&ptan) + len(&gtan);
            let w = field(c, p);
            let wn: f64 = (0..3).map(|i| w[i] * normals[v][i]).sum();
            let u: Vec<f64> = (0..3).map(|i| w[i] - wn * normals[v][i]).collect();
            let du: f64 = (0..3).map(|i| grads[v][i] * u[i]).sum();
            sum += (0..3).map(|i| pv[i] * u[i]).sum::<f64>() + pf[v] * du;
            let norm = |a: &[f64]| a.iter().map(|t| t * t).sum::<f64>().sqrt();
            size += norm(pv) * norm(&u) + (pf[v] * du).abs();
        }
        worst = worst.max(sum.abs() / size);
        worst_tan = worst_tan.max(tan_num / tan_den);
    }
    (worst, worst_tan)
}

#[test]
fn the_momentum_map_vanishes_along_optimal_trajectories() {
    // The discrete flow has no exact reparametrisation symmetry, so μ_t is
    // only as small as the discretisation error of A's invariance, O(h²)
    // (fshape-varifold's reparametrisation test). Measured for w = (sin 2y +
    // 0.5, cos z, xy), max over the 11 steps: 1.5e-2, 4.2e-3, 1.1e-3 at levels
    // 3–5; with p^f's
    // sign flipped it stays at 0.24, so the check sees the signal term.
    let c = [1.0, 0.5, 1.0, 0.0, 1.0, 0.0];
    let (r, t): (Vec<f64>, Vec<f64>) = optimals().iter().map(|o| residual(o, &c)).unzip();
    let h: Vec<f64> = (3..=5).map(|l| 0.5f64.powi(l)).collect();
    let order = observed_order(&h, &r);
    eprintln!("conservation law residuals, levels 3-5: {r:?}, order {order:.2}");
    assert!((1.5..2.5).contains(&order) && r[2] < 3e-3, "residuals {r:?}, order {order}");
    let order_tan = observed_order(&h, &t);
    eprintln!("tangential p_t + p^f ∇f_t, levels 3-5: {t:?}, order {order_tan:.2}");
    // Pointwise, so larger than the averaged residual: measured 0.16, 0.046,
    // 0.012 (order 1.84).
    assert!((1.5..2.5).contains(&order_tan) && t[2] < 0.02, "tangential residuals {t:?}, order {order_tan}");
}

proptest::proptest! {
    #![proptest_config(fshape_mesh::test_support::strategies::config(16, 5))]

    #[test]
    fn the_law_holds_for_random_smooth_tangent_fields(c in proptest::array::uniform6(-1.0f64..1.0)) {
        // Every tangent field must see μ_t ≈ 0, at every step: the residual
        // shrinks under refinement (level 3 → 5, two halvings of h: about
        // 16× at order 2; asserted ≥ 4×) and is small on the finest mesh
        // (the fixed field above gives 1.0e-3; 5e-3 leaves room for fields
        // whose terms partly cancel in the normalisation).
        let o = optimals();
        let (r3, r5) = (residual(&o[0], &c).0, residual(&o[2], &c).0);
        proptest::prop_assert!(r5 < r3 / 4.0 && r5 < 5e-3, "c = {c:?}: residual {r3:e} at level 3, {r5:e} at level 5");
    }
}

/// Σ over interior vertices of |p_t + p^f ∇f_t|, relative to
/// Σ (|p_t| + |p^f ∇f_t|), max over t = 0, 0.5, 1, on a Delaunay square of
/// about `n` vertices.
fn flat_residual(n: usize) -> f64 {
    let sq = fshape_mesh::generate::square(n, 7);
    let img = |p: &[f64]| (1.5 * p[0]).sin() * (p[1] + 0.3) + 0.5 * p[1] * p[1];
    let sig: Vec<f64> = sq.points().chunks_exact(2).map(img).collect();
    let x1 = sq.with_signal(Some(sig)).unwrap();
    let target = {
        let t = fshape_mesh::generate::square(3000, 11);
        let sig: Vec<f64> = t.points().chunks_exact(2).map(|p| (1.5 * p[0] + 0.4).sin() * (p[1] + 0.1)).collect();
        t.with_signal(Some(sig)).unwrap()
    };
    let k = VarifoldKernel::try_new(
        Kernel::gaussian(0.3).unwrap(),
        SignalKernel::Gaussian { sigma: 0.5 },
        GrassKernel::Binet,
    )
    .unwrap();
    let (_, g) = Attachment::new(&target, k).unwrap().eval_grad(&x1).unwrap();
    let m = model(0.4, "h1", 0.2, 1.0, 0.5, "rk4", 10);
    let traj = Problem::new(&x1, m).unwrap().shoot(&g.points, &g.signal).unwrap();
    let pf: Vec<f64> = g.signal.iter().map(|v| -v).collect();
    let interior: Vec<bool> =
        x1.points().chunks_exact(2).map(|p| p[0].abs() < 1.0 - 1e-9 && p[1].abs() < 1.0 - 1e-9).collect();
    let mut worst: f64 = 0.0;
    for step in [0, 5, 10] {
        let pts3: Vec<f64> = traj.points(step).chunks_exact(2).flat_map(|p| [p[0], p[1], 0.0]).collect();
        let cells = x1.cells().to_vec();
        let xt = FShape::try_new(3, x1.kind(), pts3, cells, None).unwrap();
        let grads = vertex_gradients(&xt, traj.signal(step));
        let pt = traj.momenta(step);
        let (mut num, mut den) = (0.0, 0.0);
        for v in (0..xt.n_vertices()).filter(|&v| interior[v]) {
            let (p, gf) = ([-pt[2 * v], -pt[2 * v + 1]], [pf[v] * grads[v][0], pf[v] * grads[v][1]]);
            num += ((p[0] + gf[0]).powi(2) + (p[1] + gf[1]).powi(2)).sqrt();
            den += (p[0] * p[0] + p[1] * p[1]).sqrt() + (gf[0] * gf[0] + gf[1] * gf[1]).sqrt();
        }
        worst = worst.max(num / den);
    }
    worst
}

#[test]
fn on_a_flat_domain_the_momentum_is_minus_the_signal_momentum_times_the_gradient() {
    // Image metamorphosis (paper section 3.3.3): in the plane every
    // momentum is tangential, so the law reads p_t = −p^f ∇f_t at interior
    // vertices. Measured: 1.6e-2, 6.6e-3, 3.4e-3 for about 300, 1200, 4800
    // vertices (h halving), first order; a flipped p^f gives 1.0. The
    // per-vertex gradient recovered by area-weighted averaging is only
    // first-order accurate on an irregular Delaunay mesh, which we take to
    // be what limits the order here (not isolated separately).
    let r: Vec<f64> = [300, 1200, 4800].iter().map(|&n| flat_residual(n)).collect();
    let h = [1.0, 0.5, 0.25];
    let order = observed_order(&h, &r);
    eprintln!("flat residuals: {r:?}, order {order:.2}");
    assert!((0.8..1.6).contains(&order) && r[2] < 5e-3, "residuals {r:?}, order {order}");
}

/// A random smooth scalar function of the position:
/// c₀ sin(2x + c₁) + c₂ yz + c₃ cos(z + c₄) + c₅ x.
fn smooth(c: &[f64; 6], p: &[f64; 3]) -> f64 {
    c[0] * (2.0 * p[0] + c[1]).sin() + c[2] * p[1] * p[2] + c[3] * (p[2] + c[4]).cos() + c[5] * p[0]
}

/// One random draw of a smooth closed shape with its signal, normal
/// momentum density a (and b, the second normal direction of a curve in
/// space) and signal momentum density: the same smooth functions at every
/// resolution, so that the law's residual can be watched under refinement.
#[derive(Clone, Debug)]
struct Draw {
    shape: [f64; 6],
    signal: [f64; 6],
    a: [f64; 6],
    b: [f64; 6],
    pf: [f64; 6],
    norm: &'static str,
}

fn norm3(v: [f64; 3]) -> f64 {
    v.iter().map(|t| t * t).sum::<f64>().sqrt()
}

fn cross3(u: [f64; 3], v: [f64; 3]) -> [f64; 3] {
    [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
}

/// A closed surface (`dim` = 0: the icosphere of level `n` bent by the
/// draw) or a closed curve of `n` vertices in R^`dim`, with the draw's
/// signal; per vertex its measure (a third of the adjacent triangles'
/// areas, half of the adjacent segments' lengths), a unit basis of its
/// normal space and its unit tangent (curves).
struct Discrete {
    shape: FShape,
    weight: Vec<f64>,
}

fn discretise(d: &Draw, dim: usize, n: usize) -> Discrete {
    let c = &d.shape;
    let (points, cells, kind, pdim): (Vec<f64>, Vec<usize>, _, usize) = if dim == 0 {
        let s = icosphere(n as u32, 1.0);
        let pts = s
            .points()
            .chunks_exact(3)
            .flat_map(|p| {
                let q = [p[0], p[1], p[2]];
                let r = 1.0 + 0.15 * smooth(c, &q).tanh();
                [r * (1.0 + 0.2 * c[0]) * q[0], r * q[1], r * (1.0 + 0.2 * c[3]) * q[2]]
            })
            .collect();
        (pts, s.cells().to_vec(), s.kind(), 3)
    } else {
        let mut pts = Vec::with_capacity(n * dim);
        for k in 0..n {
            let t = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
            let r = 1.0 + 0.2 * c[0] * (t + c[1]).cos() + 0.1 * c[2] * (2.0 * t + c[3]).cos();
            pts.extend([r * t.cos(), r * t.sin()]);
            if dim == 3 {
                pts.push(0.3 * c[4] * (t + c[5]).sin());
            }
        }
        let cells = (0..n).flat_map(|k| [k, (k + 1) % n]).collect();
        (pts, cells, fshape_mesh::CellKind::Segment, dim)
    };
    let at = |v: usize| -> [f64; 3] { std::array::from_fn(|k| if k < pdim { points[v * pdim + k] } else { 0.0 }) };
    let signal: Vec<f64> = (0..points.len() / pdim).map(|v| smooth(&d.signal, &at(v))).collect();
    let mut weight = vec![0.0; signal.len()];
    let corners = if dim == 0 { 3 } else { 2 };
    for cell in cells.chunks_exact(corners) {
        let (a, b) = (at(cell[0]), at(cell[1]));
        let e1: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
        let measure = if dim == 0 {
            let c3 = at(cell[2]);
            0.5 * norm3(cross3(e1, std::array::from_fn(|k| c3[k] - a[k])))
        } else {
            norm3(e1)
        };
        for &v in cell {
            weight[v] += measure / corners as f64;
        }
    }
    let shape = FShape::try_new(pdim, kind, points, cells, Some(signal)).unwrap();
    Discrete { shape, weight }
}

/// Per vertex of `s` (at positions `x`, signal `f`): a unit basis of the
/// tangent space (the orthogonal complement of the area-weighted normal
/// on a surface, the central-difference direction on a curve) and the
/// recovered signal gradient (area- or length-weighted mean of the cells'
/// gradients), both as 3-vectors.
fn tangents_and_gradients(s: &FShape, x: &[f64], f: &[f64]) -> (Vec<Vec<[f64; 3]>>, Vec<[f64; 3]>) {
    let dim = s.dim();
    let xs = s.clone().with_points(x.to_vec()).unwrap();
    let at = |v: usize| -> [f64; 3] { std::array::from_fn(|k| if k < dim { x[v * dim + k] } else { 0.0 }) };
    if s.kind() == fshape_mesh::CellKind::Triangle {
        let (g, n) = (vertex_gradients(&xs, f), vertex_normals(&xs));
        let frames = n
            .iter()
            .map(|nv| {
                let helper = if nv[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
                let t1 = cross3(*nv, helper);
                let t1 = t1.map(|v| v / norm3(t1));
                vec![t1, cross3(*nv, t1)]
            })
            .collect();
        return (frames, g);
    }
    let nv = s.n_vertices();
    let (mut g, mut w) = (vec![[0.0; 3]; nv], vec![0.0; nv]);
    for c in s.cell_iter() {
        let (a, b) = (at(c[0]), at(c[1]));
        let e: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
        let len = norm3(e);
        let ge = e.map(|v| (f[c[1]] - f[c[0]]) * v / (len * len));
        for &v in c {
            for k in 0..3 {
                g[v][k] += len * ge[k];
            }
            w[v] += len;
        }
    }
    let frames = (0..nv)
        .map(|v| {
            let (prev, next) = (at((v + nv - 1) % nv), at((v + 1) % nv));
            let t: [f64; 3] = std::array::from_fn(|k| next[k] - prev[k]);
            vec![t.map(|c| c / norm3(t))]
        })
        .collect();
    (frames, g.iter().zip(&w).map(|(gv, wv)| gv.map(|c| c / wv)).collect())
}

/// A unit basis of the normal space of a vertex, given its tangent basis.
fn normal_basis(tangents: &[[f64; 3]], dim: usize) -> Vec<[f64; 3]> {
    match (tangents, dim) {
        ([t1, t2], _) => {
            let n = cross3(*t1, *t2);
            vec![n.map(|c| c / norm3(n))]
        }
        ([t], 2) => vec![[-t[1], t[0], 0.0]],
        ([t], _) => {
            let n1 = cross3([0.0, 0.0, 1.0], *t);
            let n1 = n1.map(|c| c / norm3(n1));
            vec![n1, cross3(*t, n1)]
        }
        _ => unreachable!("one or two tangents"),
    }
}

/// Shoots the draw at one resolution from a horizontal initial momentum
/// (tangential part −p^f ∇f_0, so μ_0 = 0: random normal densities a, b
/// and signal momentum density p^f, times each vertex's measure), and
/// returns max over the steps of Σ_v |P_t(p_t + p^f ∇f_t)| / Σ_v (|P_t p_t| +
/// |p^f P_t ∇f_t|), P_t the projection on the tangent space at step t.
/// With `flip`, the flow is shot with −p^f instead (the same start, a
/// wrong signal coupling): the law must then fail.
fn horizontal_residual(d: &Draw, dim: usize, n: usize, flip: bool) -> f64 {
    let Discrete { shape, weight } = discretise(d, dim, n);
    let pdim = shape.dim();
    let f0 = shape.signal().unwrap().to_vec();
    let (frames, grads) = tangents_and_gradients(&shape, shape.points(), &f0);
    let at =
        |v: usize| -> [f64; 3] { std::array::from_fn(|k| if k < pdim { shape.points()[v * pdim + k] } else { 0.0 }) };
    let pf: Vec<f64> = (0..shape.n_vertices()).map(|v| 0.5 * smooth(&d.pf, &at(v)) * weight[v]).collect();
    let mut p0 = vec![0.0; shape.n_vertices() * pdim];
    for v in 0..shape.n_vertices() {
        let normals = normal_basis(&frames[v], pdim);
        let dens = [smooth(&d.a, &at(v)), smooth(&d.b, &at(v))];
        let mut p = [0.0; 3];
        for (nrm, a) in normals.iter().zip(dens) {
            for k in 0..3 {
                p[k] += 0.3 * a * weight[v] * nrm[k];
            }
        }
        for t in &frames[v] {
            let gt: f64 = (0..3).map(|k| grads[v][k] * t[k]).sum();
            for k in 0..3 {
                p[k] -= pf[v] * gt * t[k];
            }
        }
        p0[v * pdim..(v + 1) * pdim].copy_from_slice(&p[..pdim]);
    }
    let m = model(0.4, d.norm, 0.3, 1.0, 0.5, "rk4", 10);
    let shot_pf: Vec<f64> = pf.iter().map(|v| if flip { -v } else { *v }).collect();
    let traj = Problem::new(&shape, m).unwrap().shoot(&p0, &shot_pf).unwrap();
    let mut worst: f64 = 0.0;
    for step in 0..=traj.steps() {
        let (frames, grads) = tangents_and_gradients(&shape, traj.points(step), traj.signal(step));
        let pt = traj.momenta(step);
        let (mut num, mut den) = (0.0, 0.0);
        for v in 0..shape.n_vertices() {
            let (mut sum, mut pp, mut gg) = ([0.0; 3], [0.0; 3], [0.0; 3]);
            for t in &frames[v] {
                let ptan: f64 = (0..pdim).map(|k| pt[v * pdim + k] * t[k]).sum();
                let gtan: f64 = pf[v] * (0..3).map(|k| grads[v][k] * t[k]).sum::<f64>();
                for k in 0..3 {
                    sum[k] += (ptan + gtan) * t[k];
                    pp[k] += ptan * t[k];
                    gg[k] += gtan * t[k];
                }
            }
            num += norm3(sum);
            den += norm3(pp) + norm3(gg);
        }
        worst = worst.max(num / den);
    }
    worst
}

proptest::proptest! {
    #![proptest_config(fshape_mesh::test_support::strategies::config(12, 2026))]

    /// The conservation law on random shapes and trajectories: a smooth
    /// closed surface or curve (in the plane or in space), a smooth signal,
    /// random normal momentum and signal momentum densities and a random
    /// norm; the initial momentum is made horizontal (μ_0 = 0), and the law
    /// says μ_t stays 0 along the flow. The discrete flow keeps it up to
    /// the discretisation error, so the residual must fall under refinement
    /// (two halvings of h) and be small on the finest mesh.
    #[test]
    fn the_law_holds_along_random_horizontal_trajectories(
        dim in proptest::prop_oneof![proptest::strategy::Just(0usize), proptest::strategy::Just(2), proptest::strategy::Just(3)],
        shape in proptest::array::uniform6(-1.0f64..1.0),
        signal in proptest::array::uniform6(-1.0f64..1.0),
        a in proptest::array::uniform6(-1.0f64..1.0),
        b in proptest::array::uniform6(-1.0f64..1.0),
        pf in proptest::array::uniform6(-1.0f64..1.0),
        norm in proptest::prop_oneof![
            proptest::strategy::Just("l2-lumped"), proptest::strategy::Just("l2"), proptest::strategy::Just("h1")
        ],
    ) {
        let d = Draw { shape, signal, a, b, pf, norm };
        let sizes: [usize; 3] = if dim == 0 { [2, 3, 4] } else { [40, 80, 160] };
        let r: Vec<f64> = sizes.iter().map(|&n| horizontal_residual(&d, dim, n, false)).collect();
        let h = [1.0, 0.5, 0.25];
        let order = observed_order(&h, &r);
        let flipped = horizontal_residual(&d, dim, sizes[2], true);
        eprintln!("dim {dim} ({norm}): residuals {r:?}, order {order:.2}; shot with −p^f: {flipped:.3}");
        // Measured over 12 draws: order 1.5–1.8 on surfaces, 1.96–2.01 on
        // curves; finest residuals 4e-4 .. 5e-3. Over 30 seeds more, a draw
        // with no normal momentum (every momentum tangential, where the
        // relative residual is largest) reached 0.023 at order 1.79.
        proptest::prop_assert!(order > 1.2 && r[2] < 0.05, "{d:?}, dim {dim}: residuals {r:?}, order {order}");
        proptest::prop_assert!(flipped > 10.0 * r[2], "{d:?}, dim {dim}: shot with −p^f, residual {flipped}");
    }
}
