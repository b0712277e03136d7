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
    let mut config = Config::parse(&format!(
        "[model]\nkind = \"{kind}\"\nnorm = \"{norm}\"\nlength = 0.5\ngamma_w = 10.0\ngamma_f = 1.0\n\
         [deformation]\nwidths = [0.5]\n\
         [attachment]\nkernel_geom = \"gaussian:0.3\"\nkernel_signal = \"gaussian:1.0\"\n"
    ))
    .unwrap();
    config.integrator.steps = 4;
    config.optimizer.max_iterations = 8;
    config
}

/// The initial unknowns with random momenta of size `scale`.
fn random_point(atlas: &Atlas, scale: f64, seed: u64) -> Vec<f64> {
    let mut x = atlas.initial_unknowns();
    let t = template();
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
    for (kind, norm) in
        [("metamorphosis", "h1"), ("metamorphosis", "l2-lumped"), ("tangential", "l2"), ("lddmm", "l2-lumped")]
    {
        let mut atlas = Atlas::new(&template(), &subjects, &config(kind, norm)).unwrap();
        let x = random_point(&atlas, 0.2, 7);
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
            assert!(c.rel_error < 1e-6, "{kind}, {norm}, {what}: {c:?}");
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
        atlas.precondition(&mut w);
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
    let subjects = subjects();
    let config = config("metamorphosis", "h1");
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut atlas = Atlas::new(&template(), &subjects, &config).unwrap();
            let x = random_point(&atlas, 0.2, 9);
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
    let file = dir.join("checkpoint.json");
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
    assert!(err.contains("other inputs") && err.contains("checkpoint.json"), "{err}");
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
