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
    #![proptest_config(proptest::test_runner::Config {
        cases: 16,
        rng_seed: proptest::test_runner::RngSeed::Fixed(5),
        failure_persistence: None,
        ..proptest::test_runner::Config::default()
    })]

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
