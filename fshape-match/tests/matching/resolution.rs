//! Prolongation of momenta from a coarse template to a fine one: the
//! velocity field and the end of the shooting are kept.

use fshape_kernels::{Kernel, KernelSums};
use fshape_match::quality;
use fshape_match::resolution::prolongate;
use fshape_mesh::FShape;
use fshape_mesh::generate::icosphere;
use fshape_shoot::{Model, Problem};

/// Momenta of a smooth density on `s`: p = m·ρ(x).
fn momenta(s: &FShape) -> (Vec<f64>, Vec<f64>) {
    let m = s.vertex_volumes();
    let p0 = s
        .points()
        .chunks_exact(3)
        .zip(&m)
        .flat_map(|(x, m)| [0.2 * x[2] * m, 0.1 * x[0] * m, -0.15 * x[1] * m])
        .collect();
    let pf = s.points().chunks_exact(3).zip(&m).map(|(x, m)| (0.3 * x[0] + 0.1) * m).collect();
    (p0, pf)
}

fn relative(a: &[f64], b: &[f64]) -> f64 {
    let num: f64 = a.iter().zip(b).map(|(u, v)| (u - v).powi(2)).sum();
    (num / b.iter().map(|v| v * v).sum::<f64>()).sqrt()
}

#[test]
fn prolongated_momenta_keep_the_velocity_field_and_shoot_to_the_same_end() {
    let with_signal = |s: FShape| {
        let n = s.n_vertices();
        s.with_signal(Some(vec![0.0; n])).unwrap()
    };
    let (coarse, fine) = (with_signal(icosphere(2, 1.0)), with_signal(icosphere(4, 1.0)));
    let (p0c, pfc) = momenta(&coarse);
    let (p0f, pff) = prolongate(&coarse, &fine, &p0c, &pfc, fshape_shoot::ModelKind::Metamorphosis).unwrap();
    // The same density sampled on the fine mesh directly.
    let (p0d, pfd) = momenta(&fine);
    assert!(
        relative(&p0f, &p0d) < 0.03 && relative(&pff, &pfd) < 0.03,
        "{} {}",
        relative(&p0f, &p0d),
        relative(&pff, &pfd)
    );
    // The velocity field at the fine vertices, from either set of momenta.
    let kernel = Kernel::gaussian(0.5).unwrap();
    let velocity = |at: &FShape, p: &[f64]| {
        KernelSums::try_new(&kernel, at.points(), 3).unwrap().conv(fine.points(), p, 3).unwrap()
    };
    let (vc, vf) = (velocity(&coarse, &p0c), velocity(&fine, &p0f));
    assert!(relative(&vf, &vc) < 0.02, "velocity: {}", relative(&vf, &vc));
    // Copying the values instead (momenta as functions): 16 times too fast.
    let (copied, _) = {
        let m = fine.vertex_volumes();
        let mc = coarse.vertex_volumes();
        let scale = mc.iter().sum::<f64>() / mc.len() as f64 / (m.iter().sum::<f64>() / m.len() as f64);
        (p0f.iter().map(|p| p * scale).collect::<Vec<f64>>(), ())
    };
    assert!(relative(&velocity(&fine, &copied), &vc) > 5.0);
    // Shooting: the fine end is on the coarse end's surface, with its signal.
    let model = Model::new(kernel.clone());
    let shoot = |s: &FShape, p0: &[f64], pf: &[f64]| {
        let traj = Problem::new(s, model.clone()).unwrap().shoot(p0, pf).unwrap();
        let n = traj.steps();
        s.clone().with_points(traj.points(n).to_vec()).unwrap().with_signal(Some(traj.signal(n).to_vec())).unwrap()
    };
    let (end_c, end_f) = (shoot(&coarse, &p0c, &pfc), shoot(&fine, &p0f, &pff));
    let moved: f64 = end_f.points().iter().zip(fine.points()).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt()
        / (fine.n_vertices() as f64).sqrt();
    let q = quality(&end_f, &end_c).unwrap();
    eprintln!(
        "momenta {:.4} {:.4}, velocity {:.4}, copied {:.2}, end distance {:.5} for a displacement {moved:.4}, signal {:?}",
        relative(&p0f, &p0d),
        relative(&pff, &pfd),
        relative(&vf, &vc),
        relative(&velocity(&fine, &copied), &vc),
        q.mean_distance * q.diagonal,
        q.signal_rms
    );
    // Distances as fractions of the end's diagonal (about 2): the fine end
    // lies within a few percent of the displacement from the coarse end
    // (whose faces cut the sphere by up to 1.3 % of the radius).
    assert!(
        q.mean_distance * q.diagonal < 0.1 * moved,
        "distance {} for a displacement of {moved}",
        q.mean_distance * q.diagonal
    );
    assert!(q.signal_rms.unwrap() < 0.01, "signal error {:?}", q.signal_rms);
}
