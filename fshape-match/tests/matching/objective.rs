//! Matching end to end at small sizes: identical shapes are matched to
//! J ≈ 0, a target shot from known momenta is recovered, and the
//! configuration's optimiser and schedule sections are checked by name.

use fshape_match::optimize::{Method, Settings};
use fshape_match::session::minimize;
use fshape_match::{Config, Metric, Metrics};
use fshape_mesh::test_support::perturbed_icosphere;
use fshape_shoot::Problem;
use fshape_varifold::VarifoldKernel;

use crate::{model, momenta};

fn kernel(width: f64) -> VarifoldKernel {
    VarifoldKernel::parse(&format!("gaussian:{width}"), Some("gaussian:0.7"), "binet").unwrap()
}

fn tight(max_iterations: usize) -> Settings {
    Settings {
        method: Method::Lbfgs { memory: 10 },
        max_iterations,
        gradient_tolerance: 1e-10,
        decrease_tolerance: 0.0,
        decrease_window: 0,
        ..Settings::default()
    }
}

#[test]
fn identical_source_and_target_are_matched_from_random_momenta() {
    let shape =
        perturbed_icosphere(1, 0.05, 3).with_signal(Some((0..42).map(|i| (i as f64 * 0.3).sin()).collect())).unwrap();
    let both = Metrics { momentum: Metric::L2, signal: Metric::L2 };
    for (kind, metric) in [
        ("metamorphosis", Metrics::from(Metric::L2)),
        ("metamorphosis", Metrics::from(Metric::Euclidean)),
        ("metamorphosis", both),
        ("lddmm", Metrics::from(Metric::L2)),
        ("lddmm", both),
    ] {
        let m = model(&format!("kind = \"{kind}\""), "", "rk4", 5);
        let problem = Problem::new(&shape, m).unwrap().with_target(&shape, kernel(0.4)).unwrap();
        let (p0, pf) = momenta(&shape, 0.3, 7);
        let mut values = Vec::new();
        // ‖∇J‖ ≤ 1e-6‖∇J₀‖ near a non-degenerate minimum J* = 0 puts J at
        // ~1e-12 of its start, well below the 1e-8 asked, before line
        // searches reach the rounding of J.
        let settings = Settings { gradient_tolerance: 1e-6, ..tight(300) };
        let (state, stop, _) = minimize(&problem, metric, &p0, &pf, &settings, |s, parts| {
            assert_eq!(parts.value.to_bits(), s.value.to_bits(), "the reported parts are those of the accepted point");
            values.push(s.value);
        })
        .unwrap();
        let j0 = state.values[0];
        assert!(
            state.value < 1e-8 * j0,
            "{kind}, {metric:?}: J {:e} from {j0:e}, {stop:?} after {}",
            state.value,
            state.iteration
        );
        assert!(values.windows(2).all(|w| w[1] <= w[0]), "J decreases at every accepted step");
    }
}

#[test]
fn a_target_shot_from_known_momenta_is_recovered() {
    // Smooth known momenta on a sphere: a z-dependent radial push and a
    // signal momentum linear in x.
    let template = perturbed_icosphere(2, 0.0, 1);
    let m = model("kind = \"metamorphosis\"\nnorm = \"h1\"\nlength = 0.3\ngamma_w = 200.0", "", "rk4", 8);
    let pts = template.points();
    let p_true: Vec<f64> =
        pts.chunks_exact(3).flat_map(|x| x.iter().map(|c| 0.02 * c * (1.0 + x[2])).collect::<Vec<_>>()).collect();
    let pf_true: Vec<f64> = pts.chunks_exact(3).map(|x| 0.02 * x[0]).collect();
    let shooter = Problem::new(&template, m.clone()).unwrap();
    let traj = shooter.shoot(&p_true, &pf_true).unwrap();
    let h_true = traj.hamiltonian[0];
    let target = template
        .clone()
        .with_points(traj.points(8).to_vec())
        .unwrap()
        .with_signal(Some(traj.signal(8).to_vec()))
        .unwrap();
    let problem = Problem::new(&template, m).unwrap().with_target(&target, kernel(0.3)).unwrap();
    let zero = (vec![0.0; pts.len()], vec![0.0; template.n_vertices()]);
    let mut first = None;
    let mut last = None;
    let settings = Settings { gradient_tolerance: 1e-5, decrease_tolerance: 1e-8, decrease_window: 10, ..tight(120) };
    let (state, stop, unknowns) = minimize(&problem, Metric::L2, &zero.0, &zero.1, &settings, |_, parts| {
        first.get_or_insert(*parts);
        last = Some(*parts);
    })
    .unwrap();
    let (p0, pf) = unknowns.unpack(&state.x);
    let (start, _) = problem.objective(&zero.0, &zero.1).unwrap();
    let (end, _) = problem.objective(&p0, &pf).unwrap();
    assert_eq!(end.value.to_bits(), last.unwrap().value.to_bits());
    assert!(first.is_some());
    assert!(
        end.attachment < 1e-3 * start.attachment,
        "data term {:e} from {:e} ({stop:?}, {} iterations)",
        end.attachment,
        start.attachment,
        state.iteration
    );
    let rel = (end.energy - h_true).abs() / h_true;
    assert!(rel < 0.1, "energy {:e} against the known momenta's {h_true:e} ({rel:.3})", end.energy);
}

#[test]
fn optimizer_and_schedule_errors_name_their_key() {
    let base = "[deformation]\nwidths = [0.5]\n[attachment]\nkernel_geom = \"gaussian:0.1\"\n";
    let c = Config::parse(base).unwrap();
    let (settings, metric) = c.optimizer().unwrap();
    let defaults = Metrics { momentum: Metric::Energy, signal: Metric::L2 };
    assert_eq!((settings, metric), (Settings::default(), defaults), "documented defaults");
    assert_eq!(c.schedule().unwrap().len(), 1);
    let c = Config::parse(&format!("{base}[schedule]\nkernel_geom = [\"gaussian:0.4\", \"gaussian:0.1\"]\n")).unwrap();
    assert_eq!(
        c.schedule().unwrap().iter().map(|s| s.label.as_str()).collect::<Vec<_>>(),
        ["gaussian:0.4", "gaussian:0.1"]
    );
    for (extra, key) in [
        ("[optimizer]\nmethod = \"newton\"\n", "optimizer.method"),
        ("[optimizer]\nmemory = 0\n", "optimizer.memory"),
        ("[optimizer]\nmethod = \"gradient-descent\"\nincrease = 0.5\n", "optimizer.increase"),
        ("[optimizer]\ngradient_tolerance = -1.0\n", "optimizer.gradient_tolerance"),
        ("[optimizer]\nsignal_metric = \"h1\"\n", "optimizer.signal_metric"),
        ("[optimizer]\nmomentum_metric = \"kernel\"\n", "optimizer.momentum_metric"),
        ("[schedule]\nkernel_geom = []\n", "schedule.kernel_geom"),
        ("[schedule]\nkernel_geom = [\"gaussian:0.4\", \"gaussian:-1\"]\n", "schedule.kernel_geom[1]"),
    ] {
        // Spellings and kernels are refused when read, numbers when checked.
        let checked = Config::parse(&format!("{base}{extra}")).and_then(|c| c.optimizer().and(c.schedule()));
        let e = match checked {
            Err(e) => e.to_string(),
            Ok(_) => panic!("{extra} accepted"),
        };
        assert!(e.contains(key), "{extra}: {e}");
    }
    let e = Config::parse(&format!("{base}[optimizer]\nmax_iteration = 3\n")).unwrap_err().to_string();
    assert!(e.contains("max_iteration"), "{e}");
}

#[test]
fn a_diverging_trial_point_is_a_step_too_far_but_a_diverging_start_is_an_error() {
    use fshape_match::optimize::Objective;
    use fshape_match::session::MatchObjective;
    use fshape_match::unknowns::Unknowns;
    let shape = perturbed_icosphere(1, 0.05, 3).with_signal(Some(vec![0.0; 42])).unwrap();
    let problem = Problem::new(&shape, model("", "", "rk4", 5)).unwrap().with_target(&shape, kernel(0.4)).unwrap();
    let unknowns = Unknowns::new(&problem, Metrics::default()).unwrap();
    let huge: Vec<f64> = (0..unknowns.len()).map(|i| if i % 2 == 0 { 1e6 } else { -1e6 }).collect();
    // As the first point: the error itself, naming the divergence.
    let mut first = MatchObjective::new(&problem, unknowns.clone());
    let e = first.value_grad(&huge).expect_err("a diverging start").to_string();
    assert!(e.contains("diverged"), "{e}");
    // As a trial point after a good start: a non-finite value the line
    // search steps back from.
    let mut objective = MatchObjective::new(&problem, unknowns.clone());
    let j0 = objective.value_grad(&vec![0.0; unknowns.len()]).unwrap().value;
    assert!(j0.is_finite());
    let e = objective.value_grad(&huge).unwrap();
    let (j, g) = (e.value, e.grad);
    assert!(j.is_nan() && g.iter().all(|v| v.is_nan()));
}

/// The Delaunay square with its vertices moved by φ(t) = 0.2t + 0.8t³ on
/// each axis: edges 13 times shorter near the centre than at the sides
/// (cell areas differ by ~170).
fn graded_square(n: usize, seed: u64) -> fshape_mesh::FShape {
    let sq = fshape_mesh::generate::square(n, seed);
    let phi = |t: f64| 0.2 * t + 0.8 * t * t * t;
    let pts: Vec<f64> = sq.points().iter().map(|&t| phi(t)).collect();
    sq.with_points(pts).unwrap()
}

#[test]
fn the_first_signal_step_is_the_same_function_on_a_graded_mesh_in_the_l2_metric() {
    use fshape_match::optimize::Objective;
    use fshape_match::quality::ClosestPoints;
    use fshape_match::session::MatchObjective;
    use fshape_match::unknowns::Unknowns;
    let target = fshape_mesh::generate::square(2500, 7);
    let f: Vec<f64> = target.points().chunks_exact(2).map(|p| 0.5 * (2.0 * p[0]).sin() + 0.3 * p[1]).collect();
    let target = target.with_signal(Some(f)).unwrap();
    let uniform = fshape_mesh::generate::square(1500, 1);
    let graded = graded_square(1500, 2);
    let areas = |s: &fshape_mesh::FShape| s.vertex_volumes();
    let (ma, mb) = (areas(&uniform), areas(&graded));
    let ratio = mb.iter().cloned().fold(0.0, f64::max) / mb.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(ratio > 50.0, "the graded mesh is strongly non-uniform ({ratio})");
    let kernel = VarifoldKernel::parse("gaussian:0.2", Some("gaussian:1.0"), "binet").unwrap();
    // The signal velocity ḟ = D_0⁻¹ δp^f of the first steepest-descent step
    // (δq = −∂J/∂q) of each metric, at every vertex.
    type Step = fn(&[f64], &[f64], &[f64]) -> Vec<f64>;
    let velocity = |template: &fshape_mesh::FShape, m: &[f64], metric: Metric, step: Option<Step>| -> Vec<f64> {
        let n = template.n_vertices();
        let template = template.clone().with_signal(Some(vec![0.0; n])).unwrap();
        let problem = Problem::new(&template, model("gamma_w = 10.0", "", "rk4", 4))
            .unwrap()
            .with_target(&target, kernel.clone())
            .unwrap();
        let unknowns = Unknowns::new(&problem, Metrics { momentum: Metric::Euclidean, signal: metric }).unwrap();
        let mut objective = MatchObjective::new(&problem, unknowns.clone());
        let gq = objective.value_grad(&vec![0.0; unknowns.len()]).unwrap().grad;
        let dq: Vec<f64> = gq.iter().map(|g| -g).collect();
        let (_, dpf) = unknowns.unpack(&dq);
        match step {
            None => dpf.iter().zip(m).map(|(p, m)| p / m).collect(),
            // The step of a metric the code no longer offers, from ∂J/∂p^f.
            Some(f) => {
                let g = problem.objective_grad(&vec![0.0; 2 * n], &vec![0.0; n]).unwrap().pf;
                f(&g, m, &dpf)
            }
        }
    };
    // ‖ḟ_A − ḟ_B‖ / ‖ḟ_A‖ over the uniform mesh's area, ḟ_B interpolated
    // linearly at the uniform mesh's vertices.
    let on_b = ClosestPoints::new(&graded).unwrap();
    let difference = |va: &[f64], vb: &[f64]| -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for (i, p) in uniform.points().chunks_exact(2).enumerate() {
            let c = on_b.closest([p[0], p[1], 0.0]);
            let ids = &graded.cells()[3 * c.cell..3 * c.cell + 3];
            let interp: f64 = ids.iter().zip(c.bary).map(|(&v, w)| w * vb[v]).sum();
            num += ma[i] * (va[i] - interp).powi(2);
            den += ma[i] * va[i] * va[i];
        }
        (num / den).sqrt()
    };
    let l2 = difference(&velocity(&uniform, &ma, Metric::L2, None), &velocity(&graded, &mb, Metric::L2, None));
    let euclid =
        difference(&velocity(&uniform, &ma, Metric::Euclidean, None), &velocity(&graded, &mb, Metric::Euclidean, None));
    // The metric the code had before: δp^f = −D_0⁻¹ ∂J/∂p^f.
    let old: Step = |g, m, _| g.iter().zip(m).map(|(g, m)| -g / m / m).collect();
    let before =
        difference(&velocity(&uniform, &ma, Metric::L2, Some(old)), &velocity(&graded, &mb, Metric::L2, Some(old)));
    eprintln!(
        "relative difference of the first step's signal velocity: L2 {l2:.3}, Euclidean {euclid:.3}, D0^-1 {before:.3}"
    );
    assert!(l2 < 0.05, "the L2 step depends on the mesh: {l2}");
    assert!(euclid > 0.5 && before > 0.5, "the other metrics do not depend on it? {euclid}, {before}");
}

#[test]
fn the_first_momentum_step_moves_space_alike_on_a_graded_mesh_in_the_l2_metric() {
    use fshape_match::optimize::Objective;
    use fshape_match::session::MatchObjective;
    use fshape_match::unknowns::Unknowns;
    // The target: the square stretched along x, signal 0 like the templates.
    let target = fshape_mesh::generate::square(2500, 7);
    let pts: Vec<f64> = target.points().chunks_exact(2).flat_map(|p| [1.15 * p[0], p[1]]).collect();
    let target = target.with_points(pts).unwrap();
    let uniform = fshape_mesh::generate::square(1500, 1);
    let graded = graded_square(1500, 2);
    let kernel = VarifoldKernel::parse("gaussian:0.2", None, "binet").unwrap();
    let deformation = fshape_kernels::Kernel::gaussian(0.3).unwrap();
    // The velocity K δp_0 of the first steepest-descent step, at the
    // uniform mesh's vertices.
    let velocity = |template: &fshape_mesh::FShape, metric: Metric| -> Vec<f64> {
        let model = model("kind = \"lddmm\"\ngamma_w = 10.0", "", "rk4", 4).with_kernel(deformation.clone());
        let problem = Problem::new(template, model).unwrap().with_target(&target, kernel.clone()).unwrap();
        let unknowns = Unknowns::new(&problem, Metrics { momentum: metric, signal: Metric::L2 }).unwrap();
        let mut objective = MatchObjective::new(&problem, unknowns.clone());
        let gq = objective.value_grad(&vec![0.0; unknowns.len()]).unwrap().grad;
        let dq: Vec<f64> = gq.iter().map(|g| -g).collect();
        let (dp0, _) = unknowns.unpack(&dq);
        let sums = fshape_kernels::KernelSums::try_new(&deformation, template.points(), 2).unwrap();
        sums.conv(uniform.points(), &dp0, 2).unwrap()
    };
    let difference = |a: &[f64], b: &[f64]| -> f64 {
        let num: f64 = a.iter().zip(b).map(|(u, v)| (u - v).powi(2)).sum();
        (num / a.iter().map(|u| u * u).sum::<f64>()).sqrt()
    };
    let l2 = difference(&velocity(&uniform, Metric::L2), &velocity(&graded, Metric::L2));
    let euclid = difference(&velocity(&uniform, Metric::Euclidean), &velocity(&graded, Metric::Euclidean));
    eprintln!("relative difference of the first step's velocity field: L2 {l2:.3}, Euclidean {euclid:.3}");
    assert!(l2 < 0.1, "the L2 step depends on the mesh: {l2}");
    assert!(euclid > 3.0 * l2, "the Euclidean step does not depend on it? {euclid}");
}

#[test]
fn the_first_energy_metric_steps_are_the_same_fields_on_a_graded_mesh() {
    use fshape_match::optimize::Objective;
    use fshape_match::quality::ClosestPoints;
    use fshape_match::session::MatchObjective;
    use fshape_match::unknowns::Unknowns;
    // A target that differs in geometry (stretched along x) and signal.
    let target = fshape_mesh::generate::square(2500, 7);
    let pts: Vec<f64> = target.points().chunks_exact(2).flat_map(|p| [1.15 * p[0], p[1]]).collect();
    let f: Vec<f64> = target.points().chunks_exact(2).map(|p| 0.5 * (2.0 * p[0]).sin() + 0.3 * p[1]).collect();
    let target = target.with_points(pts).unwrap().with_signal(Some(f)).unwrap();
    let uniform = fshape_mesh::generate::square(1500, 1);
    let graded = graded_square(1500, 2);
    let kernel = VarifoldKernel::parse("gaussian:0.2", Some("gaussian:1.0"), "binet").unwrap();
    let deformation = fshape_kernels::Kernel::gaussian(0.3).unwrap();
    // The first L-BFGS direction −M⁻¹∂J/∂q in (p_0, p^f), as fields: the
    // velocity K δp_0 at the uniform mesh's vertices, and the signal
    // velocity ḟ = D_s⁻¹ δp^f (H¹, ℓ = 0.3) at the template's.
    let steps = |template: &fshape_mesh::FShape, metric: Metric| -> (Vec<f64>, Vec<f64>) {
        let n = template.n_vertices();
        let template = template.clone().with_signal(Some(vec![0.0; n])).unwrap();
        let model = model("gamma_w = 10.0\nnorm = \"h1\"\nlength = 0.3", "", "rk4", 4).with_kernel(deformation.clone());
        let problem = Problem::new(&template, model).unwrap().with_target(&target, kernel.clone()).unwrap();
        let unknowns = Unknowns::new(&problem, Metrics { momentum: metric, signal: metric }).unwrap();
        assert_eq!(unknowns.kernel_metric(), metric == Metric::Energy);
        let mut objective = MatchObjective::new(&problem, unknowns.clone());
        let mut dq = objective.value_grad(&vec![0.0; unknowns.len()]).unwrap().grad;
        objective.precondition(&mut dq);
        dq.iter_mut().for_each(|v| *v = -*v);
        let (dp0, dpf) = unknowns.unpack(&dq);
        let sums = fshape_kernels::KernelSums::try_new(&deformation, template.points(), 2).unwrap();
        let velocity = sums.conv(uniform.points(), &dp0, 2).unwrap();
        let norm = fshape_fem::SignalNorm::try_new(&template, fshape_fem::Norm::H1 { length: 0.3 }).unwrap();
        let mut solver = norm.solver().unwrap();
        solver.factor(template.points()).unwrap();
        (velocity, solver.solve(&dpf).unwrap())
    };
    let relative = |a: &[f64], b: &[f64]| -> f64 {
        let num: f64 = a.iter().zip(b).map(|(u, v)| (u - v).powi(2)).sum();
        (num / a.iter().map(|u| u * u).sum::<f64>()).sqrt()
    };
    // ḟ on the graded mesh, interpolated at the uniform mesh's vertices.
    let on_graded = ClosestPoints::new(&graded).unwrap();
    let at_uniform = |fb: &[f64]| -> Vec<f64> {
        uniform
            .points()
            .chunks_exact(2)
            .map(|p| {
                let c = on_graded.closest([p[0], p[1], 0.0]);
                let ids = &graded.cells()[3 * c.cell..3 * c.cell + 3];
                ids.iter().zip(c.bary).map(|(&v, w)| w * fb[v]).sum()
            })
            .collect()
    };
    let mut differences = Vec::new();
    for metric in [Metric::Energy, Metric::Euclidean] {
        let (va, fa) = steps(&uniform, metric);
        let (vb, fb) = steps(&graded, metric);
        differences.push((relative(&va, &vb), relative(&fa, &at_uniform(&fb))));
    }
    eprintln!(
        "relative differences (velocity, signal velocity): energy {:.3?}, Euclidean {:.3?}",
        differences[0], differences[1]
    );
    let ((v, f), (ve, fe)) = (differences[0], differences[1]);
    assert!(v < 0.1 && f < 0.1, "the energy metric's step depends on the mesh: {v}, {f}");
    assert!(ve > 3.0 * v && fe > 3.0 * f, "the Euclidean step does not depend on it? {ve}, {fe}");
}
