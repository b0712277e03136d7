//! Atlas estimation: the gradient in every unknown (template positions and
//! signal, each subject's momenta) against central differences for every
//! model, the same bits for any number of threads, resume to the same
//! bits, and a population whose template is known.

use fshape_match::{Atlas, Config, Control, Iteration, Observer, Outcome};
use fshape_mesh::FShape;
use fshape_mesh::generate::SplitMix64;
use fshape_mesh::test_support::{check_gradient, perturbed_icosphere, random_direction, random_vector_field};

/// A level-1 sphere with signal x/2 + z²/4.
fn template() -> FShape {
    let s = perturbed_icosphere(1, 0.03, 11);
    let f: Vec<f64> = s.points().chunks_exact(3).map(|p| 0.5 * p[0] + 0.25 * p[2] * p[2]).collect();
    s.with_signal(Some(f)).unwrap()
}

/// Three subjects: perturbed spheres of other resolutions, stretched
/// differently, with signals of their own.
fn subjects() -> Vec<FShape> {
    (0..3)
        .map(|i| {
            let s = perturbed_icosphere(1 + (i % 2) as u32, 0.08, 20 + i as u64);
            let a = 1.0 + 0.15 * i as f64;
            let pts: Vec<f64> = s.points().chunks_exact(3).flat_map(|p| [a * p[0], p[1], p[2] / a]).collect();
            let f: Vec<f64> = pts.chunks_exact(3).map(|p| 0.4 * p[0] + 0.1 * i as f64 * p[1]).collect();
            s.with_points(pts).unwrap().with_signal(Some(f)).unwrap()
        })
        .collect()
}

fn config(kind: &str, norm: &str) -> Config {
    config_with(kind, norm, "")
}

/// [`config`] with more lines (an `[atlas]` section).
fn config_with(kind: &str, norm: &str, more: &str) -> Config {
    let mut config = Config::parse(&format!(
        "[model]\nkind = \"{kind}\"\nnorm = \"{norm}\"\nlength = 0.5\ngamma_w = 10.0\ngamma_f = 1.0\n\
         [deformation]\nwidths = [0.5]\n\
         [attachment]\nkernel_geom = \"gaussian:0.3\"\nkernel_signal = \"gaussian:1.0\"\n{more}"
    ))
    .unwrap();
    config.integrator.steps = 4;
    config.optimizer.max_iterations = 8;
    config
}

/// The initial unknowns with random momenta of size `scale`.
fn random_point(atlas: &mut Atlas, scale: f64, seed: u64) -> Vec<f64> {
    random_point_with(atlas, scale, seed, false)
}

/// [`random_point`], with random hypertemplate momenta too if `hyper`.
fn random_point_with(atlas: &mut Atlas, scale: f64, seed: u64, hyper: bool) -> Vec<f64> {
    let mut x = atlas.initial_unknowns_at(0).unwrap();
    let t = template();
    if hyper {
        let p = random_vector_field(t.n_vertices(), 3, scale, seed + 1);
        x[..p.len()].copy_from_slice(&p);
    }
    let start = t.n_vertices() * 4;
    let noise = random_vector_field(x.len() - start, 1, scale, seed);
    for (v, n) in x[start..].iter_mut().zip(noise) {
        *v += n;
    }
    x
}

#[test]
fn the_atlas_gradient_matches_central_differences_in_every_block_for_every_model() {
    let mut rng = SplitMix64(31);
    let subjects = subjects();
    let hyper = "[atlas]\ntemplate = \"hypertemplate\"\ngamma_v0 = 0.5\n";
    for (kind, norm, more) in [
        ("metamorphosis", "h1", ""),
        ("metamorphosis", "l2-lumped", ""),
        ("tangential", "l2", ""),
        ("lddmm", "l2-lumped", ""),
        ("metamorphosis", "h1", hyper),
        ("tangential", "l2", hyper),
        ("lddmm", "l2-lumped", hyper),
    ] {
        let mut atlas = Atlas::new(&template(), &subjects, &config_with(kind, norm, more)).unwrap();
        let x = random_point_with(&mut atlas, 0.2, 7, !more.is_empty());
        let (_, grad) = atlas.value_grad(0, &x).unwrap();
        let t = template();
        let (pn, p) = (3 * t.n_vertices(), t.n_vertices());
        let per_subject = (x.len() - pn - p) / subjects.len();
        let blocks = [
            ("all", 0..x.len()),
            ("positions", 0..pn),
            ("signal", pn..pn + p),
            ("subject 1", pn + p + per_subject..pn + p + 2 * per_subject),
        ];
        let cell = std::cell::RefCell::new(&mut atlas);
        let j = |z: &[f64]| cell.borrow_mut().value_grad(0, z).unwrap().0;
        for (what, range) in blocks {
            let mut v = vec![0.0; x.len()];
            v[range.clone()].copy_from_slice(&random_direction(range.len(), &mut rng));
            let c = check_gradient(j, &x, &grad, &v, 1e-5);
            assert!(c.rel_error < 1e-6, "{kind}, {norm}, {more}, {what}: {c:?}");
        }
    }
}

#[test]
fn the_initial_hessian_shape_is_symmetric_positive_definite() {
    let mut atlas = Atlas::new(&template(), &subjects(), &config("metamorphosis", "h1")).unwrap();
    let n = atlas.len();
    let (u, v) = (random_vector_field(n, 1, 1.0, 1), random_vector_field(n, 1, 1.0, 2));
    let apply = |atlas: &mut Atlas, w: &[f64]| {
        let mut w = w.to_vec();
        atlas.precondition(0, &mut w).unwrap();
        w
    };
    let (mu, mv) = (apply(&mut atlas, &u), apply(&mut atlas, &v));
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    assert!((dot(&u, &mv) - dot(&v, &mu)).abs() < 1e-10 * dot(&u, &mu).abs().max(1.0));
    assert!(dot(&u, &mu) > 0.0 && dot(&v, &mv) > 0.0);
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn the_atlas_gives_the_same_bits_for_any_number_of_threads() {
    // H¹: its Cholesky factor's ordering comes from METIS, whose random
    // generator is process-wide; these tests run beside other atlases.
    let subjects = subjects();
    let config = config("metamorphosis", "h1");
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut atlas = Atlas::new(&template(), &subjects, &config).unwrap();
            let x = random_point(&mut atlas, 0.2, 9);
            let (j, g) = atlas.value_grad(0, &x).unwrap();
            let mut atlas = Atlas::new(&template(), &subjects, &{
                let mut c = config.clone();
                c.optimizer.max_iterations = 3;
                c
            })
            .unwrap();
            atlas.run(&mut ()).unwrap();
            let r = atlas.result().unwrap();
            (j, g, r.template.points().to_vec(), r.subjects.iter().flat_map(|s| s.p0.clone()).collect::<Vec<f64>>())
        })
    };
    let (a, b) = (run(1), run(2));
    assert_eq!(a.0.to_bits(), b.0.to_bits());
    assert_eq!(bits(&a.1), bits(&b.1));
    assert_eq!(bits(&a.2), bits(&b.2));
    assert_eq!(bits(&a.3), bits(&b.3));
}

/// Stops after `n` iterations.
struct StopAfter(usize, usize);

impl Observer for StopAfter {
    fn iteration(&mut self, _: usize, _: &Iteration) -> Control {
        self.1 += 1;
        if self.1 >= self.0 { Control::Stop } else { Control::Continue }
    }
}

#[test]
fn an_atlas_decreases_j_and_a_stopped_one_resumes_to_the_same_bits() {
    // H¹: its Cholesky factor's ordering comes from METIS, whose random
    // generator is process-wide; these tests run beside other atlases.
    let subjects = subjects();
    let config = config("metamorphosis", "h1");
    let mut whole = Atlas::new(&template(), &subjects, &config).unwrap();
    assert_eq!(whole.run(&mut ()).unwrap(), Outcome::Finished);
    let expected = whole.result().unwrap();
    let stage = &expected.stages[0];
    assert!(stage.iterations.last().unwrap().value < 0.5 * stage.initial.value, "{stage:?}");
    // Every subject is closer to its matched template than to the template.
    for s in &expected.subjects {
        assert!(s.quality.mean_distance < s.template_quality.mean_distance, "{:?}", s.quality);
    }
    let dir = std::env::temp_dir().join(format!("fshape-atlas-resume-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("checkpoint.bin");
    let mut first = Atlas::new(&template(), &subjects, &config).unwrap().with_checkpoint_file(&file);
    assert_eq!(first.run(&mut StopAfter(3, 0)).unwrap(), Outcome::Interrupted);
    let mut second = Atlas::new(&template(), &subjects, &config).unwrap().resume_from_file(&file).unwrap();
    assert_eq!(second.run(&mut ()).unwrap(), Outcome::Finished);
    let got = second.result().unwrap();
    assert_eq!(bits(got.template.points()), bits(expected.template.points()));
    assert_eq!(bits(got.template.signal().unwrap()), bits(expected.template.signal().unwrap()));
    assert_eq!(got.stages, expected.stages);
    // Another population's checkpoint is refused.
    let other = Atlas::new(&template(), &subjects[..2], &config).unwrap();
    let err = other.resume_from_file(&file).err().unwrap().to_string();
    assert!(err.contains("other inputs") && err.contains("checkpoint.bin"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_atlas_refuses_an_empty_population_and_mixed_shapes() {
    let config = config("metamorphosis", "h1");
    assert!(Atlas::new(&template(), &[], &config).err().unwrap().to_string().contains("at least one subject"));
    let curve = fshape_mesh::test_support::random_curve(3, 10, 1);
    let err = Atlas::new(&template(), &[subjects()[0].clone(), curve], &config).err().unwrap().to_string();
    assert!(err.contains("subject 1"), "{err}");
}

/// The vertex-wise mean of the subjects' positions and signals minus the
/// template's: the first-order bias of any template estimate, since a
/// template moved by it is what the mean of the subjects' geodesics points
/// to (the subjects share the template's vertices here).
fn mean_displacement(truth: &FShape, subjects: &[FShape]) -> (Vec<f64>, Vec<f64>) {
    let n = subjects.len() as f64;
    let mut dx = vec![0.0; truth.points().len()];
    let mut df = vec![0.0; truth.signal().unwrap().len()];
    for s in subjects {
        for (d, (a, b)) in dx.iter_mut().zip(s.points().iter().zip(truth.points())) {
            *d += (a - b) / n;
        }
        for (d, (a, b)) in df.iter_mut().zip(s.signal().unwrap().iter().zip(truth.signal().unwrap())) {
            *d += (a - b) / n;
        }
    }
    (dx, df)
}

#[test]
fn a_population_shot_from_a_known_template_gives_it_back_within_the_derived_bound() {
    known_template("", 0.0, 1);
    known_template("[atlas]\ntemplate = \"hypertemplate\"\ngamma_v0 = 0.1\n", 0.1, 1);
}

#[test]
fn a_population_carrying_two_maps_gives_back_the_template_and_each_of_its_maps() {
    known_template("", 0.0, 2);
}

/// The known-answer test for a template model (`more`: an `[atlas]`
/// section, or none for the free template; `gamma_v0` the hypertemplate's
/// weight, 0 without one), with one map per vertex (2z) or two (2z, 2x).
fn known_template(more: &str, gamma_v0: f64, maps: usize) {
    use fshape_shoot::Problem;
    // The truth: an ellipsoid carrying 2z (and 2x).
    let sphere = fshape_mesh::generate::icosphere(2, 0.5);
    let pts: Vec<f64> = sphere.points().chunks_exact(3).flat_map(|p| [1.3 * p[0], p[1], 0.75 * p[2]]).collect();
    let f: Vec<f64> = pts.chunks_exact(3).flat_map(|p| [2.0 * p[2], 2.0 * p[0]].into_iter().take(maps)).collect();
    let truth = sphere.clone().with_points(pts).unwrap().with_signals(Some(f), maps).unwrap();
    let widths = if maps == 1 { "0.5" } else { "0.5,0.8" };
    let mut config = Config::parse(&format!(
        "[model]\nnorm = \"h1\"\nlength = 0.3\ngamma_f = 0.1\n[deformation]\nwidths = [0.4]\n\
         [attachment]\nkernel_geom = \"gaussian:0.1\"\nkernel_signal = \"gaussian:{widths}\"\n\
         [optimizer]\ndecrease_tolerance = 1e-3\ndecrease_window = 5\nmax_iterations = 300\n",
    ))
    .unwrap();
    config.atlas = Config::parse(&format!("[deformation]\nwidths = [1.0]\n{more}")).unwrap().atlas;
    config.integrator.steps = 5;
    // Eight subjects: the truth shot by seeded random momenta.
    let plan = config.plan(&truth, &truth).unwrap();
    let shooter = Problem::new(&truth, plan.model.clone()).unwrap();
    let n = truth.n_vertices();
    let subjects: Vec<FShape> = (0..8)
        .map(|i| {
            let p0 = random_vector_field(n, 3, 0.002, 100 + i);
            let pf = random_vector_field(n, maps, 0.002, 200 + i);
            let traj = shooter.shoot(&p0, &pf).unwrap();
            let k = traj.steps();
            truth
                .clone()
                .with_points(traj.points(k).to_vec())
                .unwrap()
                .with_signals(Some(traj.signal(k).to_vec()), maps)
                .unwrap()
        })
        .collect();
    // Start from the sphere with the subjects' mean signal.
    let (_, df) = mean_displacement(&truth, &subjects);
    let mean_signal: Vec<f64> = truth.signal().unwrap().iter().zip(&df).map(|(a, b)| a + b).collect();
    let start = sphere.with_signals(Some(mean_signal), maps).unwrap();
    let mut atlas = Atlas::new(&start, &subjects, &config).unwrap();
    atlas.run(&mut ()).unwrap();
    let r = atlas.result().unwrap();
    assert_ne!(r.stages[0].stop, fshape_match::optimize::Stop::Iterations, "{:?}", r.stages[0].reason);
    // The bound: the first-order bias (the mean displacement, as a mean
    // vertex distance and an rms signal change) plus what the atlas leaves
    // unmatched (the subjects' mean distance and signal error after
    // matching); for the signal, also what the template's own position
    // error carries (below). Nothing in it is chosen: all are measured.
    let (dx, df) = mean_displacement(&truth, &subjects);
    let diag = truth.bounding_box().diagonal();
    let bias_x =
        dx.chunks_exact(3).map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()).sum::<f64>() / n as f64 / diag;
    let k = r.subjects.len() as f64;
    let residual_x = r.subjects.iter().map(|s| s.quality.mean_distance).sum::<f64>() / k;
    let got = fshape_match::quality(&r.template, &truth).unwrap();
    let before = fshape_match::quality(&start, &truth).unwrap();
    // Map c's signal error in a quality (the first's fields, else its own).
    let signal_rms = |q: &fshape_match::Quality, c: usize| {
        if c == 0 { q.signal_rms.unwrap() } else { q.channels[c].signal_rms.unwrap() }
    };
    // The hypertemplate's energy pulls the template back towards it:
    // linearised (every subject's energy ½γ_V‖y_i − x̄‖²_V, the prior's
    // ½γ_V0‖x̄ − x_HT‖²_V), the optimum sits a fraction γ_V0/(γ_V + γ_V0)
    // of the way from the subjects' mean back to the hypertemplate.
    let shrink = gamma_v0 / (1.0 + gamma_v0) * fshape_match::quality(&start, &truth).unwrap().mean_distance;
    let tol_x = bias_x + residual_x + shrink;
    eprintln!(
        "{more:?}, {maps} map(s): template vs truth: distance {:.4} (start {:.4}, bound {tol_x:.4} = bias {bias_x:.4} + residual {residual_x:.4} + shrinkage {shrink:.4})",
        got.mean_distance, before.mean_distance,
    );
    // The test has teeth: the start is well outside the bound (4.2 and
    // 3.0 times it for the free template and the hypertemplate).
    assert!(before.mean_distance > 2.5 * tol_x, "{before:?} against {tol_x}");
    assert!(got.mean_distance <= tol_x, "{got:?} against {tol_x}");
    // Each map on its own range: 2z spans 2 × 0.375 × 2, 2x 2 × 0.65 × 2.
    for (c, range) in [2.0 * 0.75 * 0.5 * 2.0, 2.0 * 1.3 * 0.5 * 2.0].into_iter().take(maps).enumerate() {
        let bias_f = (df.iter().skip(c).step_by(maps).map(|d| d * d).sum::<f64>() / n as f64).sqrt() / range;
        let residual_f = r.subjects.iter().map(|s| signal_rms(&s.quality, c)).sum::<f64>() / k;
        // A position error δ moves the closest point of a signal 2z (or
        // 2x) by up to 2δ: the signal error the geometric error alone
        // explains.
        let carried_f = 2.0 * got.mean_distance * diag / range;
        let tol_f = bias_f + residual_f + carried_f;
        let e = signal_rms(&got, c);
        eprintln!(
            "  map {}: signal {e:.4} (start {:.4}, bound {tol_f:.4} = {bias_f:.4} + {residual_f:.4} + {carried_f:.4})",
            c + 1,
            signal_rms(&before, c)
        );
        assert!(e <= tol_f, "map {}: {got:?} against {tol_f}", c + 1);
    }
}

#[test]
fn the_eigensolver_reconstructs_its_matrix_in_order_with_signs_fixed() {
    for (n, seed) in [(1, 1), (3, 4), (5, 2), (20, 3)] {
        let r = random_vector_field(n * n, 1, 1.0, seed);
        let a: Vec<f64> = (0..n * n).map(|k| r[k] + r[(k % n) * n + k / n]).collect();
        let (values, vectors) = fshape_match::linalg::symmetric_eigen(&a, n).unwrap();
        let scale = a.iter().map(|x| x.abs()).fold(0.0, f64::max);
        assert!(values.windows(2).all(|w| w[0] >= w[1]), "largest first: {values:?}");
        for i in 0..n {
            for j in 0..n {
                // V Λ Vᵀ = A and VᵀV = I.
                let back: f64 = (0..n).map(|k| vectors[i * n + k] * values[k] * vectors[j * n + k]).sum();
                let id: f64 = (0..n).map(|k| vectors[k * n + i] * vectors[k * n + j]).sum();
                assert!((back - a[i * n + j]).abs() < 1e-12 * scale);
                assert!((id - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
        // Each column's largest entry is positive, so a flipped input
        // column order or sign cannot flip a mode.
        for k in 0..n {
            let col: Vec<f64> = (0..n).map(|i| vectors[i * n + k]).collect();
            let peak = col.iter().copied().fold(0.0, |m: f64, x| if x.abs() > m.abs() { x } else { m });
            assert!(peak > 0.0, "column {k}: {col:?}");
        }
    }
    // Not finite: refused by entry.
    let e = fshape_match::linalg::symmetric_eigen(&[1.0, f64::NAN, f64::NAN, 1.0], 2).unwrap_err().to_string();
    assert!(e.contains("entry (0, 1)") && e.contains("NaN"), "{e}");
}

#[test]
fn principal_modes_are_orthonormal_in_the_energy_metric_and_their_scores_give_back_the_gram_matrix() {
    use fshape_shoot::Problem;
    let cases = [("metamorphosis", "h1", 1), ("tangential", "l2", 1), ("lddmm", "l2-lumped", 1)];
    let two_maps = [("metamorphosis", "h1", 2), ("tangential", "l2", 2)];
    for (kind, norm, maps) in cases.into_iter().chain(two_maps) {
        let (mut config, subjects, template) = if maps == 1 {
            (config(kind, norm), subjects(), template())
        } else {
            let subjects = subjects().into_iter().enumerate().map(|(i, s)| with_second_map(s, 0.1 * i as f64));
            (two_map_config(kind, norm, ""), subjects.collect(), with_second_map(template(), 0.0))
        };
        config.optimizer.max_iterations = 4;
        let mut atlas = Atlas::new(&template, &subjects, &config).unwrap();
        atlas.run(&mut ()).unwrap();
        let r = atlas.result().unwrap();
        let pca = atlas.principal_modes(&r, 10).unwrap();
        // Three subjects: at most two modes, largest first.
        assert_eq!(pca.modes.len(), 2, "{kind}");
        assert!(pca.modes.iter().all(|m| m.pf.len() == maps * r.template.n_vertices()), "{kind}");
        assert!(pca.modes[0].sd >= pca.modes[1].sd);
        let share: f64 = pca.modes.iter().map(|m| m.share).sum();
        assert!((share - 1.0).abs() < 1e-9, "{kind}: {share}");
        // ⟨m, m'⟩ by the model's own energy: the path energy J reports,
        // 2H(m) with the tangential model's signal term (γ_f/2)Σ_c w_c
        // ζ_cᵀDζ_c added (H leaves it out).
        let kernel = atlas.plan().stages[0].kernel.clone();
        let problem =
            Problem::new(&r.template, atlas.plan().model.clone()).unwrap().with_target(&r.template, kernel).unwrap();
        let norm2 = |p0: &[f64], pf: &[f64]| 2.0 * problem.objective(p0, pf).unwrap().0.energy;
        // Two maps have a weight each (1 and 2 as written).
        assert_eq!(atlas.plan().model.channel_weights().len(), if maps == 1 { 0 } else { 2 });
        let (a, b) = (&pca.modes[0], &pca.modes[1]);
        let sum = |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(x, y)| x + y).collect::<Vec<f64>>();
        assert!((norm2(&a.p0, &a.pf) - 1.0).abs() < 1e-9, "{kind}");
        assert!((norm2(&b.p0, &b.pf) - 1.0).abs() < 1e-9, "{kind}");
        // ‖a + b‖² = 2 + 2⟨a, b⟩.
        assert!((norm2(&sum(&a.p0, &b.p0), &sum(&a.pf, &b.pf)) - 2.0).abs() < 1e-9, "{kind}");
        // The scores of subjects i and j give ⟨m_i − m̄, m_j − m̄⟩.
        let centred = |i: usize| {
            let s = &r.subjects[i];
            let d0: Vec<f64> = s.p0.iter().zip(&pca.mean_p0).map(|(x, m)| x - m).collect();
            let df: Vec<f64> = s.pf.iter().zip(&pca.mean_pf).map(|(x, m)| x - m).collect();
            (d0, df)
        };
        for (i, j) in [(0, 0), (0, 1), (1, 2)] {
            let (ci, cj) = (centred(i), centred(j));
            let inner =
                0.5 * (norm2(&sum(&ci.0, &cj.0), &sum(&ci.1, &cj.1)) - norm2(&ci.0, &ci.1) - norm2(&cj.0, &cj.1));
            let from_scores: f64 = pca.scores[i].iter().zip(&pca.scores[j]).map(|(x, y)| x * y).sum();
            assert!(
                (inner - from_scores).abs() < 1e-8 * norm2(&ci.0, &ci.1).max(1e-30),
                "{kind} {i} {j}: {inner} against {from_scores}"
            );
        }
    }
}

/// A level-2 sphere carrying [`template`]'s signal formula, and a coarser
/// version of it (level 1, no signal: the atlas reads the template's).
fn fine_and_coarse() -> (FShape, FShape) {
    let s = fshape_mesh::generate::icosphere(2, 1.0);
    let f: Vec<f64> = s.points().chunks_exact(3).map(|p| 0.5 * p[0] + 0.25 * p[2] * p[2]).collect();
    (s.with_signal(Some(f)).unwrap(), fshape_mesh::generate::icosphere(1, 1.0))
}

/// [`config`] with two stages of one kernel.
fn two_stages(kind: &str, norm: &str) -> Config {
    config_with(kind, norm, "[schedule]\nkernel_geom = [\"gaussian:0.3\", \"gaussian:0.3\"]\n")
}

/// Stops when stage `0` is about to start.
struct StopAtStage(usize);

impl Observer for StopAtStage {
    fn stage_started(&mut self, k: usize, _: usize, _: &fshape_match::StageSpec, _: usize) -> Control {
        if k == self.0 { Control::Stop } else { Control::Continue }
    }
}

#[test]
fn the_atlas_gradient_on_a_coarser_stage_template_matches_central_differences() {
    let (fine, coarse) = fine_and_coarse();
    let mut atlas = Atlas::new(&fine, &subjects(), &two_stages("metamorphosis", "h1"))
        .unwrap()
        .with_stage_templates(vec![Some(coarse.clone()), None])
        .unwrap();
    assert_eq!(atlas.len_at(0), 42 * 4 + 3 * 42 * 4);
    assert_eq!(atlas.len(), 162 * 4 + 3 * 162 * 4);
    let mut x = atlas.initial_unknowns_at(0).unwrap();
    for (v, n) in x[42 * 4..].iter_mut().zip(random_vector_field(3 * 42 * 4, 1, 0.2, 5)) {
        *v += n;
    }
    let (_, grad) = atlas.value_grad(0, &x).unwrap();
    let mut rng = SplitMix64(8);
    let cell = std::cell::RefCell::new(&mut atlas);
    let j = |z: &[f64]| cell.borrow_mut().value_grad(0, z).unwrap().0;
    let dir = random_direction(x.len(), &mut rng);
    // The coarse sphere's positions give J a large third derivative: the
    // differences' error falls as h² (1.3e-4 at h = 1e-4, 1.3e-6 at 1e-5),
    // so a smaller step, and the h² fall checked.
    let (c, c10) = (check_gradient(j, &x, &grad, &dir, 3e-6), check_gradient(j, &x, &grad, &dir, 3e-5));
    assert!(c.rel_error < 1e-6 && c10.rel_error > 30.0 * c.rel_error, "{c:?} {c10:?}");
    // The stage template's signal is the template's, read at its vertices.
    let start = atlas.initial_unknowns_at(0).unwrap();
    let (t, _) = atlas.unpack(0, &start).unwrap();
    assert_eq!(t.n_vertices(), 42);
    for (p, f) in t.points().chunks_exact(3).zip(t.signal().unwrap()) {
        // Linear interpolation of 0.5x + 0.25z² on the fine faces.
        assert!((f - (0.5 * p[0] + 0.25 * p[2] * p[2])).abs() < 0.02, "{p:?}: {f}");
    }
}

#[test]
fn a_coarse_stage_solution_carried_to_the_template_keeps_its_progress_and_resumes_to_the_same_bits() {
    use fshape_shoot::Problem;
    let (fine, coarse) = fine_and_coarse();
    let subjects = subjects();
    let config = two_stages("metamorphosis", "h1");
    let build = || {
        Atlas::new(&fine, &subjects, &config).unwrap().with_stage_templates(vec![Some(coarse.clone()), None]).unwrap()
    };
    let dir = std::env::temp_dir().join(format!("fshape-atlas-levels-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("checkpoint.bin");
    let mut atlas = build().with_checkpoint_file(&file);
    assert_eq!(atlas.run(&mut StopAtStage(1)).unwrap(), Outcome::Interrupted);
    let xc = atlas.checkpoint().warm.clone().unwrap();
    let xf = atlas.prolongate_unknowns(0, &xc, 1).unwrap();
    assert_eq!(xf.len(), atlas.len());
    // J on the template keeps at least half of what the coarse stage won.
    let (start_c, start_f) = (atlas.initial_unknowns_at(0).unwrap(), atlas.initial_unknowns_at(1).unwrap());
    let won = atlas.value_grad(0, &start_c).unwrap().0 - atlas.value_grad(0, &xc).unwrap().0;
    let kept = atlas.value_grad(1, &start_f).unwrap().0 - atlas.value_grad(1, &xf).unwrap().0;
    eprintln!("J won on the coarse template {won:.4e}, kept on the template {kept:.4e}");
    assert!(won > 0.0 && kept > 0.5 * won, "won {won} on the coarse template, kept {kept}");
    // Each subject's geodesic from the carried template ends where the
    // coarse one did, up to the two templates' own distance (the coarse
    // faces cut the sphere) and a tenth of the way travelled.
    let (tc, mc) = atlas.unpack(0, &xc).unwrap();
    let (tf, mf) = atlas.unpack(1, &xf).unwrap();
    let apart = {
        let q = fshape_match::quality(&tf, &tc).unwrap();
        q.mean_distance * q.diagonal
    };
    let model = atlas.plan().model.clone();
    let shoot = |t: &FShape, (p0, pf): &(Vec<f64>, Vec<f64>)| {
        let traj = Problem::new(t, model.clone()).unwrap().shoot(p0, pf).unwrap();
        let k = traj.steps();
        t.clone().with_points(traj.points(k).to_vec()).unwrap().with_signal(Some(traj.signal(k).to_vec())).unwrap()
    };
    for (i, (a, b)) in mc.iter().zip(&mf).enumerate() {
        let (end_c, end_f) = (shoot(&tc, a), shoot(&tf, b));
        let moved = (end_f.points().iter().zip(tf.points()).map(|(u, v)| (u - v).powi(2)).sum::<f64>()
            / tf.n_vertices() as f64)
            .sqrt();
        let q = fshape_match::quality(&end_f, &end_c).unwrap();
        let d = q.mean_distance * q.diagonal;
        eprintln!("subject {i}: ends {d:.4} apart after moving {moved:.4} (templates {apart:.4} apart)");
        assert!(
            moved > 0.01 && d < apart + 0.1 * moved,
            "subject {i}: {d} apart after moving {moved} (templates {apart})"
        );
    }
    // Without the stage templates it is another run's checkpoint.
    let other = Atlas::new(&fine, &subjects, &config).unwrap().resume_from_file(&file);
    assert!(other.err().unwrap().to_string().contains("other inputs"));
    // Resumed at the switch, the run ends on the same bits as one run.
    let mut resumed = build().resume_from_file(&file).unwrap();
    assert_eq!(resumed.run(&mut ()).unwrap(), Outcome::Finished);
    let got = resumed.result().unwrap();
    let mut whole = build();
    assert_eq!(whole.run(&mut ()).unwrap(), Outcome::Finished);
    let expected = whole.result().unwrap();
    assert_eq!(bits(got.template.points()), bits(expected.template.points()));
    assert_eq!(got.stages, expected.stages);
    assert_eq!(got.template.n_vertices(), 162);
    // The fine stage started from the carried solution.
    assert_eq!(expected.stages[1].initial.value.to_bits(), atlas.value_grad(1, &xf).unwrap().0.to_bits());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn stage_templates_must_fit_the_schedule_and_the_template() {
    let (fine, coarse) = fine_and_coarse();
    let atlas = || Atlas::new(&fine, &subjects(), &two_stages("metamorphosis", "h1")).unwrap();
    let err = |r: Result<Atlas, fshape_match::MatchError>| r.err().unwrap().to_string();
    assert!(err(atlas().with_stage_templates(vec![None])).contains("1 given for a schedule of 2 stages"));
    assert!(err(atlas().with_stage_templates(vec![None, Some(coarse.clone())])).contains("must be None"));
    let curve = fshape_mesh::test_support::random_curve(3, 10, 1);
    assert!(err(atlas().with_stage_templates(vec![Some(curve), None])).contains("stage 0's template"));
    let mut a = atlas();
    let x = a.initial_unknowns_at(0).unwrap();
    assert!(a.value_grad(1, &x[1..]).err().unwrap().to_string().contains("unknowns given for stage 1"));
    assert!(
        a.value_grad(2, &x).err().unwrap().to_string().contains("stage 2 does not exist: the schedule has 2 stage(s)")
    );
}

/// Processes simulated by threads: all_gather through shared slots and a
/// barrier, as MPI's allgather.
struct Threads {
    rank: usize,
    shared: std::sync::Arc<(std::sync::Barrier, std::sync::Mutex<Vec<Vec<f64>>>)>,
}

impl fshape_match::Cluster for Threads {
    fn rank(&self) -> usize {
        self.rank
    }
    fn size(&self) -> usize {
        self.shared.1.lock().unwrap().len()
    }
    fn all_gather(&self, mine: &[f64]) -> Vec<f64> {
        let (barrier, slots) = &*self.shared;
        slots.lock().unwrap()[self.rank] = mine.to_vec();
        barrier.wait();
        let all = slots.lock().unwrap().concat();
        // Everyone has read before anyone writes the next round.
        barrier.wait();
        all
    }
}

#[test]
fn an_atlas_shared_among_processes_gives_the_bits_of_one_process() {
    let subjects = subjects();
    let mut config = config("metamorphosis", "h1");
    config.optimizer.max_iterations = 4;
    let run = |cluster: Option<Threads>| {
        let mut atlas = Atlas::new(&template(), &subjects, &config).unwrap();
        if let Some(c) = cluster {
            atlas = atlas.with_cluster(Box::new(c));
        }
        assert_eq!(atlas.run(&mut ()).unwrap(), Outcome::Finished);
        let r = atlas.result().unwrap();
        (bits(r.template.points()), bits(r.template.signal().unwrap()), r.stages)
    };
    let alone = run(None);
    // Two and three processes, and four for three subjects (one idle).
    for size in [2, 3, 4] {
        let shared =
            std::sync::Arc::new((std::sync::Barrier::new(size), std::sync::Mutex::new(vec![Vec::new(); size])));
        let results: Vec<_> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..size)
                .map(|rank| {
                    let c = Threads { rank, shared: shared.clone() };
                    let run = &run;
                    s.spawn(move || run(Some(c)))
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        for (rank, got) in results.iter().enumerate() {
            assert_eq!(got.0, alone.0, "{size} processes, rank {rank}: positions");
            assert_eq!(got.1, alone.1, "{size} processes, rank {rank}: signal");
            assert_eq!(got.2, alone.2, "{size} processes, rank {rank}: records");
        }
    }
}

/// Process `rank` of `size`, for what a process sets up (no gathering:
/// only the setup is tested here; scripts/mpi-test.sh runs real MPI).
struct Rank(usize, usize);

impl fshape_match::Cluster for Rank {
    fn rank(&self) -> usize {
        self.0
    }
    fn size(&self) -> usize {
        self.1
    }
    fn all_gather(&self, mine: &[f64]) -> Vec<f64> {
        mine.to_vec()
    }
}

#[test]
fn each_process_sets_up_only_its_own_subjects() {
    // Seven subjects over three processes: blocks of 2, 2 and 3.
    let subjects: Vec<FShape> = (0..7).map(|i| subjects()[i % 3].clone()).collect();
    let c = config("metamorphosis", "h1");
    let mut alone = Atlas::new(&template(), &subjects, &c).unwrap();
    assert_eq!(alone.subjects_set_up(), 0, "nothing before a stage needs it");
    let start = alone.initial_unknowns().unwrap();
    assert_eq!(alone.subjects_set_up(), 7);
    for (rank, held) in [(0, 2), (1, 2), (2, 3)] {
        let mut atlas = Atlas::new(&template(), &subjects, &c).unwrap().with_cluster(Box::new(Rank(rank, 3)));
        assert_eq!(atlas.initial_unknowns().unwrap(), start, "every process starts from the same unknowns");
        assert_eq!(atlas.subjects_set_up(), held, "process {rank}");
    }
}

#[test]
fn with_prealign_every_subject_is_moved_onto_the_initial_template_first() {
    // The subjects turned by a quarter turn about z and shifted far away:
    // aligned, each starts at least as close to the initial template as
    // the plain subject does (the undone turn is one candidate of the
    // fit; these near-spheres may also fit turned about their axes).
    let turned: Vec<FShape> = subjects()
        .iter()
        .map(|s| {
            let pts = s.points().chunks_exact(3).flat_map(|p| [-p[1] + 2.0, p[0] - 1.0, p[2] + 0.5]).collect();
            s.clone().with_points(pts).unwrap()
        })
        .collect();
    let config = config_with("metamorphosis", "h1", "[prealign]\nkind = \"rigid\"\n");
    let mut atlas = Atlas::new(&template(), &turned, &config).unwrap();
    atlas.run(&mut ()).unwrap();
    let result = atlas.result().unwrap();
    let mut plain = Atlas::new(&template(), &subjects(), &config_with("metamorphosis", "h1", "")).unwrap();
    plain.run(&mut ()).unwrap();
    let plain = plain.result().unwrap();
    for (i, (s, p)) in result.subjects.iter().zip(&plain.subjects).enumerate() {
        let a = s.alignment.as_ref().expect("every subject aligned");
        assert!(a.attachment_after < a.attachment_before, "subject {i}: {a:?}");
        assert!(
            s.initial_attachment <= p.initial_attachment * (1.0 + 1e-6),
            "subject {i}: aligned {} against plain {}",
            s.initial_attachment,
            p.initial_attachment
        );
        assert!(p.alignment.is_none());
    }
    assert!(result.energies.value < result.stages[0].initial.value);
}

/// The template's mesh with its signal and a polar cap z > 0.6 masked
/// (the medial wall's stand-in), the signal there set to `fill`.
fn masked_on_template(signal_scale: f64, fill: f64) -> FShape {
    let t = template();
    let mask: Vec<f64> = t.points().chunks_exact(3).map(|p| if p[2] > 0.6 { 0.0 } else { 1.0 }).collect();
    let f: Vec<f64> =
        t.signal().unwrap().iter().zip(&mask).map(|(f, m)| if *m == 0.0 { fill } else { signal_scale * f }).collect();
    t.with_signal_and_mask(Some(f), Some(mask)).unwrap()
}

#[test]
fn a_masked_population_gives_its_mask_to_the_template_and_its_wall_is_never_read() {
    // On the template's mesh: two subjects masked on the cap, one not.
    let bare = || template().with_signal(None).unwrap();
    let subjects = |fill: f64| vec![masked_on_template(1.0, fill), masked_on_template(3.0, fill), template()];
    let initial = fshape_match::atlas::initial_template(bare(), &subjects(f64::NAN)).unwrap();
    // Every vertex has a value in the third subject: nothing is masked,
    // and the cap's signal is the third subject's alone.
    let truth = template();
    let (f, f0) = (initial.signal().unwrap(), truth.signal().unwrap());
    let cap: Vec<bool> = initial.points().chunks_exact(3).map(|p| p[2] > 0.6).collect();
    assert!(initial.mask().unwrap().iter().all(|m| *m == 1.0));
    for v in 0..f.len() {
        let want = if cap[v] { f0[v] } else { (1.0 + 3.0 + 1.0) * f0[v] / 3.0 };
        assert!((f[v] - want).abs() <= 1e-15 * want.abs().max(1.0), "vertex {v}: {} against {want}", f[v]);
    }
    // Without the third, the cap is masked on the template too.
    let two = |fill: f64| subjects(fill)[..2].to_vec();
    let initial = fshape_match::atlas::initial_template(bare(), &two(f64::NAN)).unwrap();
    let mask = initial.mask().unwrap();
    assert!(cap.iter().zip(mask).all(|(c, m)| *m == if *c { 0.0 } else { 1.0 }));

    // J and its gradient do not read a masked value, and the template's
    // masked signal has no gradient.
    let config = config("metamorphosis", "h1");
    let eval = |fill: f64| {
        let mut atlas = Atlas::new(&initial, &two(fill), &config).unwrap();
        let x = random_point(&mut atlas, 0.2, 3);
        let (j, g) = atlas.value_grad(0, &x).unwrap();
        (x, j, g)
    };
    let (x, j, g) = eval(f64::NAN);
    assert!(j.is_finite() && x.iter().all(|v| v.is_finite()));
    for fill in [0.0, 1e300] {
        let (_, j2, g2) = eval(fill);
        assert_eq!((j.to_bits(), bits(&g)), (j2.to_bits(), bits(&g2)), "masked values {fill}");
    }
    let pn = 3 * initial.n_vertices();
    for v in (0..initial.n_vertices()).filter(|&v| cap[v]) {
        assert_eq!(g[pn + v], 0.0, "the masked vertex {v}'s signal has a gradient");
    }
    let mut atlas = Atlas::new(&initial, &two(f64::NAN), &config).unwrap();
    let mut rng = SplitMix64(8);
    let cell = std::cell::RefCell::new(&mut atlas);
    let c = check_gradient(
        |z| cell.borrow_mut().value_grad(0, z).unwrap().0,
        &x,
        &g,
        &random_direction(x.len(), &mut rng),
        1e-5,
    );
    assert!(c.rel_error < 1e-6, "{c:?}");

    // A run ends with the mask on the template and on every matched state.
    let mut atlas = Atlas::new(&initial, &two(f64::NAN), &config).unwrap();
    assert_eq!(atlas.run(&mut ()).unwrap(), Outcome::Finished);
    let result = atlas.result().unwrap();
    assert_eq!(result.template.mask(), initial.mask());
    assert!(result.template.signal().unwrap().iter().zip(&cap).all(|(f, c)| f.is_nan() == *c));
    assert!(result.energies.value.is_finite());
}

/// `s` with a second map beside its signal: 0.3 z + `shift` y.
fn with_second_map(s: FShape, shift: f64) -> FShape {
    let first = s.signal().unwrap().to_vec();
    let f: Vec<f64> = s.points().chunks_exact(3).zip(first).flat_map(|(p, f)| [f, 0.3 * p[2] + shift * p[1]]).collect();
    s.with_signals(Some(f), 2).unwrap()
}

/// [`config_with`] for two maps: a width each and weights 1 and 2.
fn two_map_config(kind: &str, norm: &str, more: &str) -> Config {
    let mut config = config_with(kind, norm, more);
    let maps = Config::parse(
        "[model]\nchannel_weights = [1.0, 2.0]\n[deformation]\nwidths = [0.5]\n[attachment]\nkernel_geom = \"gaussian:0.3\"\n\
         kernel_signal = \"gaussian:1.0,0.7\"\n",
    )
    .unwrap();
    config.model.channel_weights = maps.model.channel_weights;
    config.attachment = maps.attachment;
    config
}

#[test]
fn with_two_maps_the_atlas_gradient_matches_central_differences_in_every_block() {
    let mut rng = SplitMix64(41);
    let subjects: Vec<FShape> =
        subjects().into_iter().enumerate().map(|(i, s)| with_second_map(s, 0.1 * i as f64)).collect();
    let template = with_second_map(template(), 0.0);
    let (n, pn) = (template.n_vertices(), 3 * template.n_vertices());
    let p = 2 * n;
    let hyper = "[atlas]\ntemplate = \"hypertemplate\"\ngamma_v0 = 0.5\n";
    for (kind, norm, more) in [
        ("metamorphosis", "h1", ""),
        ("tangential", "l2", ""),
        ("lddmm", "l2-lumped", ""),
        ("metamorphosis", "h1", hyper),
    ] {
        let mut atlas = Atlas::new(&template, &subjects, &two_map_config(kind, norm, more)).unwrap();
        let per_subject = 3 * n + if kind == "lddmm" { 0 } else { p };
        assert_eq!(atlas.len(), pn + p + 3 * per_subject, "{kind}");
        let mut x = atlas.initial_unknowns_at(0).unwrap();
        // The template's maps are unknowns in their own units: read back.
        let (t, _) = atlas.unpack(0, &x).unwrap();
        for (a, b) in t.signal().unwrap().iter().zip(template.signal().unwrap()) {
            assert!((a - b).abs() <= 1e-15 * b.abs(), "{kind}: {a} read back as {b}");
        }
        let noise = random_vector_field(x.len(), 1, 0.2, 9);
        let from = if more.is_empty() { pn + p } else { 0 };
        for (v, e) in x[from..].iter_mut().zip(&noise[from..]) {
            *v += e;
        }
        let (_, grad) = atlas.value_grad(0, &x).unwrap();
        let cell = std::cell::RefCell::new(&mut atlas);
        let j = |z: &[f64]| cell.borrow_mut().value_grad(0, z).unwrap().0;
        for (what, range) in [
            ("all", 0..x.len()),
            ("positions", 0..pn),
            ("maps", pn..pn + p),
            ("subject 1", pn + p + per_subject..pn + p + 2 * per_subject),
        ] {
            let mut v = vec![0.0; x.len()];
            v[range.clone()].copy_from_slice(&random_direction(range.len(), &mut rng));
            // The hypertemplate's shooting gives J a large third
            // derivative in P_0: a smaller step there.
            let h = if more.is_empty() { 1e-5 } else { 3e-6 };
            let c = check_gradient(j, &x, &grad, &v, h);
            assert!(c.rel_error < 1e-6, "{kind}, {norm}, {more}, {what}: {c:?}");
        }
    }
}

#[test]
fn with_two_maps_a_coarse_stage_reads_both_maps_and_carries_its_solution_to_the_template() {
    // The free template and the hypertemplate (whose momenta P_0 are
    // carried to the finer stage as LDDMM momenta).
    for more in ["", "[atlas]\ntemplate = \"hypertemplate\"\ngamma_v0 = 0.5\n"] {
        two_maps_on_a_coarse_stage(more);
    }
}

fn two_maps_on_a_coarse_stage(more: &str) {
    let (fine, coarse) = fine_and_coarse();
    let fine = with_second_map(fine, 0.0);
    let subjects: Vec<FShape> =
        subjects().into_iter().enumerate().map(|(i, s)| with_second_map(s, 0.1 * i as f64)).collect();
    let config = two_map_config(
        "metamorphosis",
        "h1",
        &format!("[schedule]\nkernel_geom = [\"gaussian:0.3\", \"gaussian:0.3\"]\n{more}"),
    );
    let mut atlas =
        Atlas::new(&fine, &subjects, &config).unwrap().with_stage_templates(vec![Some(coarse), None]).unwrap();
    assert_eq!(atlas.len_at(0), 42 * 5 + 3 * 42 * 5);
    assert_eq!(atlas.len(), 162 * 5 + 3 * 162 * 5);
    // The stage template's maps are the template's, read at its vertices.
    let start = atlas.initial_unknowns_at(0).unwrap();
    let (t, _) = atlas.unpack(0, &start).unwrap();
    assert_eq!(t.n_channels(), 2);
    for (p, f) in t.points().chunks_exact(3).zip(t.signal().unwrap().chunks_exact(2)) {
        assert!((f[0] - (0.5 * p[0] + 0.25 * p[2] * p[2])).abs() < 0.02, "{p:?}: {f:?}");
        assert!((f[1] - 0.3 * p[2]).abs() < 0.02, "{p:?}: {f:?}");
    }
    // The gradient on the coarse stage, then a run through both stages:
    // the template keeps two maps, each subject's p^f has two a vertex.
    let mut x = start.clone();
    for (v, e) in x[42 * 5..].iter_mut().zip(random_vector_field(3 * 42 * 5, 1, 0.2, 5)) {
        *v += e;
    }
    let (_, grad) = atlas.value_grad(0, &x).unwrap();
    let mut rng = SplitMix64(12);
    let dir = random_direction(x.len(), &mut rng);
    let cell = std::cell::RefCell::new(&mut atlas);
    let j = |z: &[f64]| cell.borrow_mut().value_grad(0, z).unwrap().0;
    let c = check_gradient(j, &x, &grad, &dir, 3e-6);
    assert!(c.rel_error < 1e-6, "{more}: {c:?}");
    assert_eq!(atlas.run(&mut ()).unwrap(), Outcome::Finished);
    let r = atlas.result().unwrap();
    assert_eq!((r.template.n_vertices(), r.template.n_channels()), (162, 2));
    assert!(r.subjects.iter().all(|s| s.pf.len() == 2 * 162 && s.quality.channels.len() == 2));
    assert!(r.stages.iter().all(|s| s.iterations.last().is_some_and(|i| i.value < s.initial.value)), "{:?}", r.stages);
    let modes = atlas.principal_modes(&r, 2).unwrap();
    assert!(modes.modes.iter().all(|m| m.pf.len() == 2 * 162));
}
