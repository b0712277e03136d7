//! Matching end to end at small sizes: identical shapes are matched to
//! J ≈ 0, a target shot from known momenta is recovered, and the
//! configuration's optimiser and schedule sections are checked by name.

use fshape_match::optimize::{Method, Settings};
use fshape_match::unknowns::minimize;
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
    let defaults = Metrics { momentum: Metric::Euclidean, signal: Metric::L2 };
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
