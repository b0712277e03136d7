//! Every `MatchError` variant, triggered through the public API: the
//! variant is the one that names the problem, and its message says what
//! went wrong and where.

use fshape_match::{Atlas, Checkpoint, Cluster, Config, MatchError, Session};
use fshape_mesh::test_support::perturbed_icosphere;
use fshape_mesh::{CellKind, FShape};

/// A sphere with a signal, another as target, a two-stage configuration.
fn pair() -> (FShape, FShape, Config) {
    let source = perturbed_icosphere(1, 0.0, 1);
    let f: Vec<f64> = source.points().chunks_exact(3).map(|p| p[2]).collect();
    let source = source.with_signal(Some(f)).unwrap();
    let target = perturbed_icosphere(1, 0.08, 2);
    let g: Vec<f64> = target.points().chunks_exact(3).map(|p| 0.5 * p[0]).collect();
    let target = target.with_signal(Some(g)).unwrap();
    let config = Config::parse(&two_stages("")).unwrap();
    (source, target, config)
}

fn two_stages(more: &str) -> String {
    format!(
        "[model]\ngamma_w = 10.0\ngamma_f = 1.0\n[deformation]\nwidths = [0.5]\n\
         [attachment]\nkernel_geom = \"gaussian:0.3\"\nkernel_signal = \"gaussian:1.0\"\n\
         [integrator]\nsteps = 3\n\
         [schedule]\nkernel_geom = [\"gaussian:0.6\", \"gaussian:0.3\"]\n{more}"
    )
}

/// An atlas of two subjects.
fn atlas() -> Atlas {
    let (template, target, config) = pair();
    Atlas::new(&template, &[target.clone(), target], &config).unwrap()
}

/// Process 0 of two, whose partner sends what `other` makes of a record.
struct Partner<F: Fn(&[f64]) -> Vec<f64>>(F);

impl<F: Fn(&[f64]) -> Vec<f64>> Cluster for Partner<F> {
    fn rank(&self) -> usize {
        0
    }
    fn size(&self) -> usize {
        2
    }
    fn all_gather(&self, mine: &[f64]) -> Vec<f64> {
        let mut all = mine.to_vec();
        all.extend((self.0)(mine));
        all
    }
}

fn message(e: &MatchError) -> String {
    e.to_string()
}

#[test]
fn a_value_out_of_range_names_its_key() {
    let (source, target, _) = pair();
    let config = Config::parse(&two_stages("").replace("gamma_w = 10.0", "gamma_w = -1.0")).unwrap();
    let e = Session::new(&source, &target, &config).err().expect("refused");
    assert!(matches!(&e, MatchError::Config { key, .. } if key == "model.gamma_w"), "{e}");
    assert!(message(&e).contains("model.gamma_w"), "{e}");
}

#[test]
fn a_syntax_error_names_the_line() {
    let e = Config::parse("[model]\ngamma_w = \n").unwrap_err();
    assert!(matches!(e, MatchError::ConfigSyntax { .. }), "{e}");
    assert!(message(&e).contains("line 2"), "{e}");
}

#[test]
fn a_missing_file_names_the_file() {
    let e = Config::read(std::path::Path::new("/nonexistent/fshape.toml")).unwrap_err();
    assert!(matches!(e, MatchError::File { .. }), "{e}");
    assert!(message(&e).starts_with("/nonexistent/fshape.toml: "), "{e}");
}

#[test]
fn a_damaged_checkpoint_file_names_the_file_and_the_damage() {
    let e = Checkpoint::from_bytes(b"not a checkpoint").unwrap_err();
    assert!(matches!(e, MatchError::Checkpoint { .. }), "{e}");
    let dir = std::env::temp_dir().join(format!("fshape-match-errors-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("damaged.ckpt");
    std::fs::write(&file, b"not a checkpoint").unwrap();
    let e = Checkpoint::read(&file).unwrap_err();
    assert!(
        matches!(&e, MatchError::InFile { source, .. } if matches!(**source, MatchError::Checkpoint { .. })),
        "{e}"
    );
    assert!(message(&e).contains(&file.display().to_string()), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn shapes_of_two_kinds_are_named_with_their_kinds() {
    let (source, _, config) = pair();
    let curve = fshape_mesh::generate::circle(20, 1.0);
    let e = Session::new(&source, &curve, &config).err().expect("refused");
    assert!(matches!(e, MatchError::Kinds(_)), "{e}");
    assert!(message(&e).contains("triangle") && message(&e).contains("segment"), "{e}");
}

#[test]
fn a_result_before_the_end_is_refused() {
    let (source, target, config) = pair();
    let e = Session::new(&source, &target, &config).unwrap().result().expect_err("refused");
    assert!(matches!(e, MatchError::NotFinished), "{e}");
}

#[test]
fn stage_templates_that_do_not_fit_the_schedule_say_how() {
    let (source, target, config) = pair();
    let e = Session::new(&source, &target, &config).unwrap().with_stage_templates(vec![None]).err().expect("refused");
    assert!(matches!(e, MatchError::StageTemplates(_)), "{e}");
    assert!(message(&e).contains("1 given for a schedule of 2 stages"), "{e}");
    let e = atlas().with_stage_templates(vec![None, Some(source)]).err().expect("refused");
    assert!(matches!(e, MatchError::StageTemplates(_)), "{e}");
}

#[test]
fn stage_templates_given_twice_are_refused() {
    let (source, target, _) = pair();
    let config = Config::parse(&two_stages("vertices = [20]\n")).unwrap();
    let coarse = perturbed_icosphere(0, 0.0, 1);
    let e = Session::new(&source, &target, &config)
        .unwrap()
        .with_stage_templates(vec![Some(coarse), None])
        .err()
        .expect("refused");
    assert!(matches!(e, MatchError::StageTemplatesTwice), "{e}");
}

#[test]
fn a_mesh_the_simplifier_cannot_take_names_the_stage() {
    // Curves are not simplified: stage 0 asks for 10 of a circle's 40 vertices.
    let circle = |n: usize| {
        let c = fshape_mesh::generate::circle(n, 1.0);
        let f: Vec<f64> = c.points().chunks_exact(2).map(|p| p[0]).collect();
        c.with_signal(Some(f)).unwrap()
    };
    let config = Config::parse(&two_stages("vertices = [10]\n")).unwrap();
    let e = Session::new(&circle(40), &circle(30), &config).err().expect("refused");
    assert!(matches!(e, MatchError::Simplify { stage: 0, vertices: 10, .. }), "{e}");
    assert!(message(&e).contains("stage 0"), "{e}");
}

#[test]
fn a_stage_beyond_the_schedule_is_named() {
    let e = atlas().initial_unknowns_at(5).unwrap_err();
    assert!(matches!(e, MatchError::NoSuchStage { stage: 5, stages: 2 }), "{e}");
}

#[test]
fn unknowns_of_the_wrong_length_are_counted() {
    let e = atlas().value_grad(0, &[0.0; 3]).unwrap_err();
    assert!(matches!(e, MatchError::UnknownsLength { stage: 0, got: 3, .. }), "{e}");
}

#[test]
fn an_atlas_without_subjects_is_refused() {
    let (template, _, config) = pair();
    let e = Atlas::new(&template, &[], &config).err().expect("refused");
    assert!(matches!(e, MatchError::NoSubjects), "{e}");
}

#[test]
fn a_shape_without_cells_is_degenerate() {
    let points = FShape::try_new(3, CellKind::Triangle, vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0], vec![], None).unwrap();
    let e = fshape_match::quality::ClosestPoints::new(&points).err().expect("refused");
    assert!(matches!(e, MatchError::Degenerate(_)), "{e}");
}

#[test]
fn processes_out_of_step_are_named() {
    let mut atlas = atlas().with_cluster(Box::new(Partner(|_: &[f64]| Vec::new())));
    let x = atlas.initial_unknowns().unwrap();
    let e = atlas.value_grad(0, &x).unwrap_err();
    assert!(matches!(e, MatchError::Gather { .. }), "{e}");
}

#[test]
fn a_subject_failing_on_another_process_names_the_subject_and_process() {
    // The partner's record: status 2 (failed), then zeros.
    let failed = |mine: &[f64]| {
        let mut r = vec![0.0; mine.len()];
        r[0] = 2.0;
        r
    };
    let mut atlas = atlas().with_cluster(Box::new(Partner(failed)));
    let x = atlas.initial_unknowns().unwrap();
    let e = atlas.value_grad(0, &x).unwrap_err();
    assert!(matches!(e, MatchError::Remote { subject: 1, rank: 1 }), "{e}");
}

#[test]
fn a_diverging_shooting_is_the_shooting_s_error() {
    let mut atlas = atlas();
    let x = vec![1e300; atlas.len_at(0)];
    let e = atlas.value_grad(0, &x).unwrap_err();
    assert!(matches!(e, MatchError::Shoot(_)), "{e}");
}

#[test]
fn a_mean_signal_that_overflows_is_the_mesh_s_error() {
    let template = perturbed_icosphere(1, 0.0, 1).with_signal(None).unwrap();
    let n = template.n_vertices();
    let subject = template.clone().with_signal(Some(vec![f64::MAX; n])).unwrap();
    let e = fshape_match::atlas::initial_template(template, &[subject.clone(), subject]).unwrap_err();
    assert!(matches!(e, MatchError::Shape(_)), "{e}");
}

#[test]
fn a_displaced_pair_without_a_signal_is_invalid_input() {
    let bare = perturbed_icosphere(1, 0.0, 1).with_signal(None).unwrap();
    let e = fshape_match::demo::displaced(&bare, 0.1, 0.5, 1).expect_err("refused");
    assert!(matches!(e, MatchError::InvalidInput(_)), "{e}");
    assert!(message(&e).contains("needs a signal"), "{e}");
}
