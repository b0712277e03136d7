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

/// The unit icospheres of levels 2 (162 vertices) and 4 (2562), with a
/// zero signal.
fn spheres() -> (FShape, FShape) {
    let with_signal = |s: FShape| {
        let n = s.n_vertices();
        s.with_signal(Some(vec![0.0; n])).unwrap()
    };
    (with_signal(icosphere(2, 1.0)), with_signal(icosphere(4, 1.0)))
}

#[test]
fn prolongated_momenta_keep_the_velocity_field_and_shoot_to_the_same_end() {
    let (coarse, fine) = spheres();
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
    let (end_c, end_f) = (shoot_end(&coarse, &kernel, &p0c, &pfc), shoot_end(&fine, &kernel, &p0f, &pff));
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

/// The end of shooting `p0`, `pf` from `s` with `kernel`.
fn shoot_end(s: &FShape, kernel: &Kernel, p0: &[f64], pf: &[f64]) -> FShape {
    let traj = Problem::new(s, Model::new(kernel.clone())).unwrap().shoot(p0, pf).unwrap();
    let n = traj.steps();
    s.clone().with_points(traj.points(n).to_vec()).unwrap().with_signal(Some(traj.signal(n).to_vec())).unwrap()
}

/// Momenta that are not a smooth density, as a coarse optimum's are: the
/// density transfer loses part of their velocity field, the fit keeps it,
/// and the fitted momenta shoot closer to the coarse end.
#[test]
fn fitted_momenta_keep_the_velocity_of_rough_momenta() {
    use fshape_match::resolution::prolongate_fitted;
    use fshape_mesh::test_support::random_vector_field;
    let (coarse, fine) = spheres();
    let kernel = Kernel::gaussian(0.3).unwrap();
    // Independent momenta at each coarse vertex, of a density about 3:
    // displacements of a third of the radius.
    let mc = coarse.vertex_volumes();
    let p0c: Vec<f64> =
        random_vector_field(coarse.n_vertices(), 3, 3.0, 7).iter().enumerate().map(|(i, p)| p * mc[i / 3]).collect();
    let pfc = vec![0.0; coarse.n_vertices()];
    let kind = fshape_shoot::ModelKind::Metamorphosis;
    let (p0d, pfd) = prolongate(&coarse, &fine, &p0c, &pfc, kind).unwrap();
    let (p0f, pff) = prolongate_fitted(&coarse, &fine, &p0c, &pfc, kind, &kernel).unwrap();
    assert_eq!(pff, pfd, "the signal momentum is carried as a density either way");
    let velocity = |at: &FShape, p: &[f64]| {
        KernelSums::try_new(&kernel, at.points(), 3).unwrap().conv(fine.points(), p, 3).unwrap()
    };
    let vc = velocity(&coarse, &p0c);
    let (err_d, err_f) = (relative(&velocity(&fine, &p0d), &vc), relative(&velocity(&fine, &p0f), &vc));
    let (end_c, end_d, end_f) = (
        shoot_end(&coarse, &kernel, &p0c, &pfc),
        shoot_end(&fine, &kernel, &p0d, &pfd),
        shoot_end(&fine, &kernel, &p0f, &pff),
    );
    // Surface distances to the coarse end (whose flat faces set a floor).
    let (qd, qf) = (quality(&end_d, &end_c).unwrap(), quality(&end_f, &end_c).unwrap());
    let moved: f64 = end_f.points().iter().zip(fine.points()).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt()
        / (fine.n_vertices() as f64).sqrt();
    eprintln!(
        "velocity error: density {err_d:.2e}, fit {err_f:.2e}; end distance density {:.2e}, fit {:.2e}, displacement {moved:.3}",
        qd.mean_distance * qd.diagonal,
        qf.mean_distance * qf.diagonal
    );
    // The fit solves for the velocity at the fine vertices; its ridge
    // (1e-6 of the diagonal) leaves an error far below the quadrature's.
    assert!(err_f < 1e-3 && err_f < err_d / 10.0, "velocity error: density {err_d}, fit {err_f}");
    assert!(qf.mean_distance < 0.9 * qd.mean_distance, "{qf:?} {qd:?}");
    // Scaled in length with the kernel, the transfer is the same, up to
    // rounding amplified by the solve's conditioning (about 1/ε = 10⁶).
    let scaled = |s: &FShape| s.clone().with_points(s.points().iter().map(|x| 10.0 * x).collect()).unwrap();
    let (p0s, _) =
        prolongate_fitted(&scaled(&coarse), &scaled(&fine), &p0c, &pfc, kind, &Kernel::gaussian(3.0).unwrap()).unwrap();
    assert!(relative(&p0s, &p0f) < 1e-6, "scaled: {}", relative(&p0s, &p0f));
    // The fit of templates beyond the dense limit (conjugate gradients on
    // the fast sums, from the densities) keeps most of what they lose.
    let fit = fshape_match::resolution::VelocityFit::iterative(&fine, &kernel).unwrap();
    let (p0i, pfi) = fit.carry(&coarse, &p0c, &pfc, kind).unwrap();
    assert_eq!(pfi, pfd);
    let err_i = relative(&velocity(&fine, &p0i), &vc);
    eprintln!("velocity error, iterative fit: {err_i:.2e}");
    assert!(err_i < err_d / 20.0, "velocity error: density {err_d}, iterative fit {err_i}");
}

#[test]
fn momenta_and_signals_of_two_channels_are_carried_as_each_channel_alone() {
    // Per channel, the same bits as a one-channel shape carrying that
    // channel: the channels are interleaved, never mixed.
    let (coarse1, fine1) = spheres();
    let (p0, pf_a) = momenta(&coarse1);
    let pf_b: Vec<f64> = pf_a.iter().enumerate().map(|(i, v)| v * (1.0 + (i % 7) as f64) - 0.01).collect();
    let two = |s: &FShape, a: &[f64], b: &[f64]| -> FShape {
        let rows = a.iter().zip(b).flat_map(|(x, y)| [*x, *y]).collect();
        s.clone().with_signals(Some(rows), 2).unwrap()
    };
    let (signal_a, signal_b): (Vec<f64>, Vec<f64>) =
        coarse1.points().chunks_exact(3).map(|x| (x[0] + 0.5 * x[1], x[2] * x[2])).unzip();
    let coarse2 = two(&coarse1, &signal_a, &signal_b);
    let fine2 = two(&fine1, &vec![0.0; fine1.n_vertices()], &vec![0.0; fine1.n_vertices()]);
    let rows: Vec<f64> = pf_a.iter().zip(&pf_b).flat_map(|(x, y)| [*x, *y]).collect();
    for kind in [fshape_shoot::ModelKind::Metamorphosis, fshape_shoot::ModelKind::Tangential] {
        let (q0, qf) = prolongate(&coarse2, &fine2, &p0, &rows, kind).unwrap();
        assert_eq!(qf.len(), 2 * fine1.n_vertices());
        for (c, pf) in [&pf_a, &pf_b].into_iter().enumerate() {
            let (q0_1, qf_1) = prolongate(&coarse1, &fine1, &p0, pf, kind).unwrap();
            assert_eq!(q0, q0_1, "{kind:?}: p_0");
            let got: Vec<f64> = qf.iter().skip(c).step_by(2).copied().collect();
            assert_eq!(got, qf_1, "{kind:?}: channel {c}");
        }
    }
    // Resampling the signal: each channel as itself alone.
    let (rows, _) = fshape_match::resolution::sample_signal(&coarse2, &fine1).unwrap();
    for (c, f) in [&signal_a, &signal_b].into_iter().enumerate() {
        let one = coarse1.clone().with_signal(Some(f.clone())).unwrap();
        let (alone, _) = fshape_match::resolution::sample_signal(&one, &fine1).unwrap();
        let got: Vec<f64> = rows.iter().skip(c).step_by(2).copied().collect();
        assert_eq!(got, alone, "channel {c}");
    }
}
