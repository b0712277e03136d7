//! The optimiser on functions with known minimisers: a convex quadratic
//! and Rosenbrock's function; the strong Wolfe conditions at every accepted
//! step; non-finite values; the objective's errors; checkpoint and resume.

use fshape_match::optimize::{Evaluation, Method, Objective, Settings, State, Step, Stop};

/// J and ∇J, or a test's error.
type Eval = Result<(f64, Vec<f64>), ()>;

/// ½ xᵀA x − bᵀx with A = diag(1..n) + 0.5·(ones), minimiser A⁻¹b.
fn quadratic(n: usize) -> (impl FnMut(&[f64]) -> Eval, Vec<f64>) {
    let a = move |i: usize, j: usize| if i == j { (i + 1) as f64 + 0.5 } else { 0.5 };
    let b: Vec<f64> = (0..n).map(|i| (i as f64).sin() + 1.0).collect();
    // The minimiser, by Sherman–Morrison on D + 0.5·11ᵀ (independent of
    // the optimiser): x = D⁻¹b − (0.5·1ᵀD⁻¹b / (1 + 0.5·1ᵀD⁻¹1)) D⁻¹1.
    let dinv_b: Vec<f64> = (0..n).map(|i| b[i] / (i + 1) as f64).collect();
    let dinv_1: Vec<f64> = (0..n).map(|i| 1.0 / (i + 1) as f64).collect();
    let c = 0.5 * dinv_b.iter().sum::<f64>() / (1.0 + 0.5 * dinv_1.iter().sum::<f64>());
    let xstar: Vec<f64> = dinv_b.iter().zip(&dinv_1).map(|(u, v)| u - c * v).collect();
    let f = move |x: &[f64]| {
        let ax: Vec<f64> = (0..n).map(|i| (0..n).map(|j| a(i, j) * x[j]).sum()).collect();
        let value = 0.5 * x.iter().zip(&ax).map(|(u, v)| u * v).sum::<f64>()
            - x.iter().zip(&b).map(|(u, v)| u * v).sum::<f64>();
        let grad = ax.iter().zip(&b).map(|(u, v)| u - v).collect();
        Ok((value, grad))
    };
    (f, xstar)
}

/// The n-dimensional Rosenbrock function, minimum 0 at (1, …, 1).
fn rosenbrock(x: &[f64]) -> Result<(f64, Vec<f64>), ()> {
    let n = x.len();
    let mut value = 0.0;
    let mut grad = vec![0.0; n];
    for i in 0..n - 1 {
        let (a, b) = (x[i + 1] - x[i] * x[i], 1.0 - x[i]);
        value += 100.0 * a * a + b * b;
        grad[i] += -400.0 * a * x[i] - 2.0 * b;
        grad[i + 1] += 200.0 * a;
    }
    Ok((value, grad))
}

fn strict(method: Method) -> Settings {
    Settings {
        method,
        max_iterations: 2000,
        gradient_tolerance: 1e-12,
        decrease_tolerance: 0.0,
        decrease_window: 0,
        ..Settings::default()
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(u, v)| u * v).sum()
}

#[test]
fn lbfgs_and_gradient_descent_find_the_minimiser_of_a_quadratic() {
    // Stopping at ‖∇J‖ ≤ 1e-8‖∇J₀‖ (‖∇J₀‖ = ‖b‖ ≈ 3.4) puts x within
    // ‖∇J‖/λ_min ≤ 3.4e-8/1.5 of the minimiser; 1e-7 allows for that.
    // (Much tighter gradient tolerances are out of reach of any line search
    // on values: near the minimum J changes by less than its rounding.)
    for method in [Method::Lbfgs { memory: 10 }, Method::GradientDescent { increase: 1.2 }] {
        let (mut f, xstar) = quadratic(8);
        let mut state = State::start(vec![0.0; 8], &mut f).unwrap().0;
        let settings = Settings { gradient_tolerance: 1e-8, ..strict(method) };
        let stop = state.run(&settings, &mut f, |_| {}).unwrap();
        let err = state.x.iter().zip(&xstar).map(|(u, v)| (u - v).abs()).fold(0.0, f64::max);
        assert_eq!(stop, Stop::Gradient, "{method:?}");
        assert!(err < 1e-7, "{method:?}: stopped ({stop:?}) at distance {err:e} after {} iterations", state.iteration);
        if let Method::Lbfgs { .. } = method {
            // Eight distinct eigenvalues: L-BFGS needs a few dozen steps at
            // most (gradient descent, with condition number ~9, many more).
            assert!(state.iteration < 40, "{} iterations", state.iteration);
        }
    }
}

/// ½ xᵀA x − bᵀx in two blocks of 10 unknowns with curvatures (1..10) and
/// 1e-4·(1..10), coupled by 0.1·(e_0 e_10ᵀ + e_10 e_0ᵀ) (scaled so A stays
/// positive definite) — the geometry and signal momenta of a matching, in
/// miniature. It names its blocks to the optimiser.
struct TwoScales;

impl TwoScales {
    const N: usize = 20;
    fn a(i: usize, j: usize) -> f64 {
        let d = |k: usize| if k < 10 { (k + 1) as f64 } else { 1e-4 * (k - 9) as f64 };
        match (i, j) {
            _ if i == j => d(i),
            (0, 10) | (10, 0) => 0.1 * (d(0) * d(10)).sqrt(),
            _ => 0.0,
        }
    }
    fn b(i: usize) -> f64 {
        if i < 10 { 1.0 + i as f64 } else { 1e-4 * (1.0 + (i as f64).cos()) }
    }
    /// The minimiser, solved independently: the blocks are diagonal except
    /// the (0, 10) pair, a 2 × 2 system by Cramer's rule.
    fn minimiser() -> Vec<f64> {
        let mut x: Vec<f64> = (0..Self::N).map(|i| Self::b(i) / Self::a(i, i)).collect();
        let (a00, a01, a11) = (Self::a(0, 0), Self::a(0, 10), Self::a(10, 10));
        let det = a00 * a11 - a01 * a01;
        x[0] = (Self::b(0) * a11 - a01 * Self::b(10)) / det;
        x[10] = (a00 * Self::b(10) - a01 * Self::b(0)) / det;
        x
    }
}

impl Objective for TwoScales {
    type Error = ();
    type Parts = ();
    fn value_grad(&mut self, x: &[f64]) -> Result<Evaluation<()>, ()> {
        let n = Self::N;
        let ax: Vec<f64> = (0..n).map(|i| (0..n).map(|j| Self::a(i, j) * x[j]).sum()).collect();
        let value = (0..n).map(|i| 0.5 * x[i] * ax[i] - Self::b(i) * x[i]).sum();
        Ok((value, (0..n).map(|i| ax[i] - Self::b(i)).collect()).into())
    }
    fn blocks(&self) -> Vec<usize> {
        vec![10]
    }
}

#[test]
fn block_scaled_lbfgs_reaches_the_minimiser_of_a_two_scale_quadratic_in_fewer_iterations() {
    let xstar = TwoScales::minimiser();
    let mut runs = Vec::new();
    for block_scaling in [true, false] {
        let settings = Settings { block_scaling, gradient_tolerance: 1e-10, ..strict(Method::Lbfgs { memory: 5 }) };
        let mut state = State::start(vec![0.0; TwoScales::N], &mut TwoScales).unwrap().0;
        let stop = state.run(&settings, &mut TwoScales, |_| {}).unwrap();
        // Relative error per block: the second block's values are O(1) too
        // (b and A both scaled by 1e-4).
        let err = state.x.iter().zip(&xstar).map(|(u, v)| (u - v).abs() / v.abs().max(1.0)).fold(0.0, f64::max);
        runs.push((stop, state.iteration, err));
    }
    let (stop, iterations, err) = runs[0];
    assert!(
        stop == Stop::Gradient && err < 1e-6,
        "block-scaled: {stop:?} after {iterations} iterations, error {err:e}"
    );
    // One γ for both blocks: the second block's curvature is invisible
    // beside the first's, so it crawls (here it ends in a failed line search
    // far from the minimiser, after hundreds of steps).
    let (stop1, iterations1, err1) = runs[1];
    assert!(
        stop1 != Stop::Gradient || iterations1 > 2 * iterations,
        "single γ: {stop1:?} after {iterations1} iterations (error {err1:e}); block-scaled: {iterations}"
    );
}

#[test]
fn lbfgs_minimises_rosenbrock_and_every_step_meets_the_strong_wolfe_conditions() {
    for n in [2, 10] {
        let mut x0 = vec![-1.2; n];
        x0.iter_mut().skip(1).step_by(2).for_each(|v| *v = 1.0);
        let mut f = rosenbrock;
        let mut state = State::start(x0, &mut f).unwrap().0;
        let mut prev = state.clone();
        let settings = strict(Method::Lbfgs { memory: 7 });
        let stop = state
            .run(&settings, &mut f, |s| {
                // s_k = x_{k+1} − x_k = t·d, so the conditions read, with
                // c1 = 1e-4 and c2 = 0.9:
                let step: Vec<f64> = s.x.iter().zip(&prev.x).map(|(a, b)| a - b).collect();
                let slope0 = dot(&prev.grad, &step);
                assert!(slope0 < 0.0, "a descent direction");
                assert!(s.value <= prev.value + 1e-4 * slope0, "sufficient decrease at iteration {}", s.iteration);
                assert!(dot(&s.grad, &step).abs() <= 0.9 * slope0.abs(), "curvature at iteration {}", s.iteration);
                prev = s.clone();
            })
            .unwrap();
        let err = state.x.iter().map(|v| (v - 1.0).abs()).fold(0.0, f64::max);
        assert!(state.value < 1e-16 && err < 1e-7, "n = {n}: {stop:?}, J = {:e}, |x − 1| = {err:e}", state.value);
        assert!(state.iteration < 150, "n = {n}: {} iterations", state.iteration);
    }
}

#[test]
fn the_stopping_rules_fire_and_say_why() {
    let (mut f, _) = quadratic(5);
    let gradient = Settings { gradient_tolerance: 1e-3, decrease_tolerance: 0.0, ..Settings::default() };
    let mut s = State::start(vec![0.0; 5], &mut f).unwrap().0;
    assert_eq!(s.run(&gradient, &mut f, |_| {}).unwrap(), Stop::Gradient);
    let g = s.grad.iter().map(|v| v * v).sum::<f64>().sqrt();
    assert!(g <= 1e-3 * s.grad_norm0);

    let iterations = Settings { max_iterations: 3, ..strict(Method::Lbfgs { memory: 5 }) };
    let mut s = State::start(vec![0.0; 5], &mut f).unwrap().0;
    assert_eq!(s.run(&iterations, &mut f, |_| {}).unwrap(), Stop::Iterations);
    assert_eq!((s.iteration, s.values.len()), (3, 4));

    // A relative decrease of 1e300 over one iteration can never be met
    // (from x = 3·1, where J > 0).
    let decrease = Settings { decrease_tolerance: 1e300, decrease_window: 1, ..strict(Method::Lbfgs { memory: 5 }) };
    let mut s = State::start(vec![3.0; 5], &mut f).unwrap().0;
    assert!(s.value > 0.0);
    assert_eq!(s.run(&decrease, &mut f, |_| {}).unwrap(), Stop::Decrease);
    assert_eq!(s.iteration, 1);
}

#[test]
fn non_finite_values_are_reported_or_stepped_back_from_and_errors_pass_through() {
    // NaN at the start: reported, no iteration.
    let mut nan = |_: &[f64]| -> Result<(f64, Vec<f64>), ()> { Ok((f64::NAN, vec![0.0])) };
    let mut s = State::start(vec![1.0], &mut nan).unwrap().0;
    assert_eq!(s.run(&Settings::default(), &mut nan, |_| {}).unwrap(), Stop::NonFiniteStart);
    assert_eq!(s.iteration, 0);

    // J = (x − 3)² but undefined (NaN) beyond x = 2.5 (a shooting that
    // diverges for large momenta): the searches step back inside, no
    // NaN is ever accepted, and the run ends at the boundary region's best.
    let mut walled = |x: &[f64]| -> Result<(f64, Vec<f64>), ()> {
        if x[0] > 2.5 { Ok((f64::NAN, vec![f64::NAN])) } else { Ok(((x[0] - 3.0).powi(2), vec![2.0 * (x[0] - 3.0)])) }
    };
    for method in [Method::Lbfgs { memory: 5 }, Method::GradientDescent { increase: 2.0 }] {
        let mut s = State::start(vec![0.0], &mut walled).unwrap().0;
        let settings = Settings { max_iterations: 50, ..Settings::default() };
        s.run(&settings, &mut walled, |st| assert!(st.value.is_finite() && st.x[0] <= 2.5)).unwrap();
        assert!(s.x[0] > 2.0 && s.x[0] <= 2.5, "{method:?}: {}", s.x[0]);
    }

    // The objective's own error comes back unchanged.
    let mut calls = 0;
    let mut failing = |x: &[f64]| -> Result<(f64, Vec<f64>), String> {
        calls += 1;
        if calls > 5 { Err("shooting diverged at step 4".into()) } else { Ok(rosenbrock(x).unwrap()) }
    };
    let mut s = State::start(vec![-1.2, 1.0], &mut failing).unwrap().0;
    assert_eq!(s.run(&Settings::default(), &mut failing, |_| {}), Err("shooting diverged at step 4".to_string()));
}

#[test]
fn a_run_resumed_from_a_checkpoint_is_bitwise_the_uninterrupted_run() {
    let settings = strict(Method::Lbfgs { memory: 4 });
    let x0: Vec<f64> = (0..6).map(|i| if i % 2 == 0 { -1.2 } else { 1.0 }).collect();
    let mut f = rosenbrock;
    let mut whole = State::start(x0.clone(), &mut f).unwrap().0;
    for _ in 0..25 {
        whole.iterate(&settings, &mut f).unwrap();
    }
    let mut part = State::start(x0, &mut f).unwrap().0;
    for _ in 0..11 {
        part.iterate(&settings, &mut f).unwrap();
    }
    // Through JSON text, as `fshape match` writes it.
    let text = serde_json::to_string(&part).unwrap();
    let mut resumed: State = serde_json::from_str(&text).unwrap();
    assert_eq!(resumed, part, "the checkpoint round trip is exact");
    for _ in 11..25 {
        resumed.iterate(&settings, &mut f).unwrap();
    }
    assert_eq!(
        resumed.x.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        whole.x.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    assert_eq!(resumed, whole);
}

/// Rosenbrock's function reporting, as its parts, the point it was
/// evaluated at and its value, so that a test can tell whose parts the
/// optimiser hands back.
struct Reporting;

impl Objective for Reporting {
    type Error = ();
    type Parts = (Vec<f64>, f64);
    fn value_grad(&mut self, x: &[f64]) -> Result<Evaluation<(Vec<f64>, f64)>, ()> {
        let (value, grad) = rosenbrock(x)?;
        Ok(Evaluation { value, grad, parts: (x.to_vec(), value) })
    }
}

#[test]
fn the_parts_handed_back_are_those_of_the_accepted_point() {
    // Rosenbrock from (−1.2, 1, …) makes both line searches bracket, zoom
    // and sometimes reject their last trial: the accepted point is not
    // always the last evaluated.
    let x0: Vec<f64> = (0..4).map(|i| if i % 2 == 0 { -1.2 } else { 1.0 }).collect();
    for method in [Method::Lbfgs { memory: 5 }, Method::GradientDescent { increase: 2.0 }] {
        let settings = Settings { max_iterations: 60, ..strict(method) };
        let (mut state, (at, value)) = State::start(x0.clone(), &mut Reporting).unwrap();
        assert_eq!((&at, value.to_bits()), (&x0, state.value.to_bits()), "{method:?}: the start's parts");
        let (mut accepted, mut evaluations) = (0, state.evaluations);
        loop {
            match state.iterate(&settings, &mut Reporting).unwrap() {
                Step::Stopped(_) => break,
                Step::Accepted((at, value)) => {
                    assert_eq!(at, state.x, "{method:?}, iteration {}: the parts' point", state.iteration);
                    assert_eq!(value.to_bits(), state.value.to_bits());
                    accepted += 1;
                }
            }
            evaluations = state.evaluations;
        }
        assert_eq!(accepted, state.iteration);
        assert!(evaluations > accepted + 1, "{method:?}: the searches evaluated more points than they accepted");
    }
}
