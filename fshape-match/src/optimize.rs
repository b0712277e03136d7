//! Minimisation of a smooth objective from its value and gradient: L-BFGS
//! with a line search satisfying the strong Wolfe conditions, and the
//! paper's gradient descent with an adaptive step.
//!
//! Written here rather than taken from argmin because matching needs three
//! things argmin's executor does not give directly: the complete state
//! between iterations as plain data ([`State`], serde), so that a run
//! stopped after any iteration resumes to a result bitwise identical to an
//! uninterrupted one; the objective's error type (a shooting that diverges)
//! passed through unchanged; and every non-finite value stopped and
//! reported rather than searched past. The algorithms are the textbook
//! ones: Nocedal & Wright, *Numerical Optimization* (2nd ed.), Algorithm
//! 7.4 (two-loop recursion, initial scaling γ = sᵀy/yᵀy) and Algorithms
//! 3.5–3.6 (bracketing and zoom with safeguarded cubic interpolation).
//!
//! One addition: an objective whose unknowns come in blocks of different
//! units (matching: momenta of the geometry, then of the signal) may name
//! them ([`Objective::blocks`]), and L-BFGS then starts its two-loop
//! recursion from a block-diagonal H₀ = diag(γ_b I), each γ_b = s_bᵀy_b /
//! y_bᵀy_b from the newest pair restricted to block b. H₀ stays positive
//! definite (a block without positive curvature falls back to the global
//! γ), so the update keeps its guarantees (N&W 7.2: any positive definite
//! H₀ is allowed); a single γ instead makes the first block's curvature
//! set the step of the other, which left one block frozen in the demos.
//! An objective may also give the shape of H₀ ([`Objective::precondition`],
//! M⁻¹, positive definite and block-diagonal): then H₀ = diag(γ_b M_b⁻¹)
//! with γ_b = s_bᵀy_b / y_bᵀM_b⁻¹y_b, and the first direction is −M⁻¹∇J
//! (matching: the energy metric of the momenta, [`crate::precondition`]).

use std::collections::VecDeque;

/// Which method, and its parameter.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Method {
    /// L-BFGS keeping `memory` correction pairs.
    Lbfgs {
        /// Number of (s, y) pairs kept (fshapesTk and most codes: 5–20).
        memory: usize,
    },
    /// Gradient descent with the paper's adaptive step: after an accepted
    /// step the next trial step grows by `increase`; a step that does not
    /// decrease J enough (Armijo, c₁ = 1e-4) is halved until it does.
    GradientDescent {
        /// Growth factor after a success (> 1).
        increase: f64,
    },
}

/// When to stop.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Settings {
    /// The method.
    pub method: Method,
    /// At most this many iterations (accepted steps).
    pub max_iterations: usize,
    /// Stop when ‖∇J‖ ≤ this × ‖∇J‖ at the start.
    pub gradient_tolerance: f64,
    /// Stop when J fell by less than this relative amount over the last
    /// `decrease_window` iterations: (J_{k−w} − J_k) ≤ tol·|J_{k−w}|.
    pub decrease_tolerance: f64,
    /// The window of the relative-decrease test.
    pub decrease_window: usize,
    /// Objective evaluations allowed per line search.
    pub max_evaluations_per_search: usize,
    /// L-BFGS: scale each block of [`Objective::blocks`] by its own
    /// curvature (module docs); false: one γ for all unknowns.
    pub block_scaling: bool,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            method: Method::Lbfgs { memory: 10 },
            max_iterations: 200,
            gradient_tolerance: 1e-3,
            decrease_tolerance: 1e-6,
            decrease_window: 10,
            max_evaluations_per_search: 20,
            block_scaling: true,
        }
    }
}

/// Why a minimisation stopped.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Stop {
    /// ‖∇J‖ fell below the tolerance relative to its start.
    Gradient,
    /// J decreased by less than the tolerance over the window.
    Decrease,
    /// The iteration limit was reached.
    Iterations,
    /// The line search found no acceptable step (at the accuracy of f64,
    /// J cannot be decreased along the search direction any more).
    LineSearch,
    /// The objective or its gradient was not finite at the start.
    NonFiniteStart,
}

impl Stop {
    /// A sentence for reports.
    pub fn describe(&self) -> &'static str {
        match self {
            Stop::Gradient => "the gradient norm fell below the tolerance relative to its start",
            Stop::Decrease => "the objective decreased by less than the tolerance over the window",
            Stop::Iterations => "the iteration limit was reached",
            Stop::LineSearch => "the line search found no step that decreases the objective",
            Stop::NonFiniteStart => "the objective or its gradient is not finite at the starting point",
        }
    }
}

/// The whole optimiser state between two iterations: serialise it to
/// checkpoint, deserialise it to resume (the continuation is bitwise the
/// same as without the interruption).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct State {
    /// Current point.
    pub x: Vec<f64>,
    /// J(x).
    pub value: f64,
    /// ∇J(x).
    pub grad: Vec<f64>,
    /// ‖∇J‖ at the first point.
    pub grad_norm0: f64,
    /// Accepted steps so far.
    pub iteration: usize,
    /// Objective evaluations so far.
    pub evaluations: usize,
    /// J after each iteration, J(x₀) first.
    pub values: Vec<f64>,
    /// The last accepted step length (gradient descent's next trial is
    /// `increase` times it).
    pub step: f64,
    /// L-BFGS correction pairs, oldest first.
    pub s: VecDeque<Vec<f64>>,
    /// Gradient differences matching `s`.
    pub y: VecDeque<Vec<f64>>,
    /// Set once a stopping rule fired.
    pub stopped: Option<Stop>,
}

/// J and ∇J at a point, with whatever else the objective reports of it
/// (matching: J's parts, [`fshape_shoot::Energies`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Evaluation<P> {
    /// J(x).
    pub value: f64,
    /// ∇J(x).
    pub grad: Vec<f64>,
    /// What else the objective reports at x.
    pub parts: P,
}

impl From<(f64, Vec<f64>)> for Evaluation<()> {
    fn from((value, grad): (f64, Vec<f64>)) -> Self {
        Evaluation { value, grad, parts: () }
    }
}

/// An objective: J and ∇J at x (and its parts), or the caller's error.
pub trait Objective {
    /// The caller's error (passed through unchanged).
    type Error;
    /// What an evaluation reports besides J and ∇J, handed back with the
    /// point the optimiser accepts ([`Step::Accepted`]); `()` for nothing.
    type Parts: Clone;
    /// J(x), ∇J(x) and the parts.
    fn value_grad(&mut self, x: &[f64]) -> Result<Evaluation<Self::Parts>, Self::Error>;
    /// Where the unknowns split into blocks of different units: the start
    /// of every block but the first, increasing. Default: one block.
    fn blocks(&self) -> Vec<usize> {
        Vec::new()
    }
    /// Applies the shape M⁻¹ of L-BFGS's initial inverse Hessian (positive
    /// definite, block-diagonal in [`Objective::blocks`]) to `v`: the
    /// direction without correction pairs is −M⁻¹∇J, and each block's
    /// γ_b M_b⁻¹ starts the two-loop recursion. Default: the identity.
    fn precondition(&self, v: &mut [f64]) {
        let _ = v;
    }
}

impl<E, F: FnMut(&[f64]) -> Result<(f64, Vec<f64>), E>> Objective for F {
    type Error = E;
    type Parts = ();
    fn value_grad(&mut self, x: &[f64]) -> Result<Evaluation<()>, E> {
        self(x).map(Evaluation::from)
    }
}

/// What one iteration did.
#[derive(Clone, Debug, PartialEq)]
pub enum Step<P> {
    /// A point was accepted; the objective's parts at it.
    Accepted(P),
    /// A stopping rule holds (nothing changed).
    Stopped(Stop),
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(u, v)| u * v).sum()
}

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

fn finite(value: f64, grad: &[f64]) -> bool {
    value.is_finite() && grad.iter().all(|g| g.is_finite())
}

impl State {
    /// Evaluates J at the starting point: the state, and the objective's
    /// parts there.
    pub fn start<O: Objective>(x0: Vec<f64>, objective: &mut O) -> Result<(State, O::Parts), O::Error> {
        let Evaluation { value, grad, parts } = objective.value_grad(&x0)?;
        let ok = finite(value, &grad);
        let state = State {
            grad_norm0: norm(&grad),
            x: x0,
            value,
            grad,
            iteration: 0,
            evaluations: 1,
            values: vec![value],
            step: 0.0,
            s: VecDeque::new(),
            y: VecDeque::new(),
            stopped: (!ok).then_some(Stop::NonFiniteStart),
        };
        Ok((state, parts))
    }

    /// The stopping rule that holds now, if any.
    fn check(&self, settings: &Settings) -> Option<Stop> {
        if self.stopped.is_some() {
            return self.stopped;
        }
        if norm(&self.grad) <= settings.gradient_tolerance * self.grad_norm0 {
            return Some(Stop::Gradient);
        }
        let w = settings.decrease_window;
        if w > 0 && self.values.len() > w {
            let old = self.values[self.values.len() - 1 - w];
            if old - self.value <= settings.decrease_tolerance * old.abs() {
                return Some(Stop::Decrease);
            }
        }
        if self.iteration >= settings.max_iterations {
            return Some(Stop::Iterations);
        }
        None
    }

    /// The first trial step along −∇J: the linear model's step to J = 0,
    /// |J|/‖∇J‖² (matching objectives are ≥ 0 with minimum near 0), but at
    /// most a move of length 1 (1/‖∇J‖) and at most 1. A step too long
    /// (a shooting that folds the mesh) costs one halving per evaluation, a
    /// step too short one doubling, so a scale-aware start saves both.
    /// `d`: the first direction, −M⁻¹∇J (−∇J without a preconditioner).
    fn first_step(&self, d: &[f64]) -> f64 {
        let slope = -dot(d, &self.grad);
        let linear = if self.value != 0.0 { self.value.abs() / slope } else { f64::INFINITY };
        linear.min(1.0 / norm(d)).min(1.0)
    }

    /// The L-BFGS direction −H∇J (two-loop recursion); −M⁻¹∇J without
    /// pairs (`precondition` applies M⁻¹, [`Objective::precondition`]).
    /// `blocks`: starts of the blocks after the first, each scaled by its
    /// own γ (module docs); empty for one γ.
    fn lbfgs_direction(&self, blocks: &[usize], precondition: impl Fn(&mut [f64])) -> Vec<f64> {
        let mut q = self.grad.clone();
        let k = self.s.len();
        let mut alpha = vec![0.0; k];
        let rho: Vec<f64> = (0..k).map(|i| 1.0 / dot(&self.y[i], &self.s[i])).collect();
        for i in (0..k).rev() {
            alpha[i] = rho[i] * dot(&self.s[i], &q);
            for (qj, yj) in q.iter_mut().zip(&self.y[i]) {
                *qj -= alpha[i] * yj;
            }
        }
        // H_0 = diag(γ_b M_b⁻¹), γ_b = s_bᵀy_b / y_bᵀM_b⁻¹y_b (M = I: N&W's
        // γ = sᵀy/yᵀy).
        precondition(&mut q);
        if k > 0 {
            let (s, y) = (&self.s[k - 1], &self.y[k - 1]);
            let mut my = y.clone();
            precondition(&mut my);
            let gamma = dot(s, y) / dot(y, &my);
            // Block bounds 0 < b₁ < … < n; starts out of order or range
            // are skipped rather than trusted.
            let n = q.len();
            let mut bounds = vec![0];
            for &b in blocks {
                if b > bounds[bounds.len() - 1] && b < n {
                    bounds.push(b);
                }
            }
            bounds.push(n);
            for w in bounds.windows(2) {
                let (a, b) = (w[0], w[1]);
                let (sy, yy) = (dot(&s[a..b], &y[a..b]), dot(&y[a..b], &my[a..b]));
                let g = if sy > 0.0 && yy > 0.0 && (sy / yy).is_finite() { sy / yy } else { gamma };
                q[a..b].iter_mut().for_each(|v| *v *= g);
            }
        }
        for i in 0..k {
            let beta = rho[i] * dot(&self.y[i], &q);
            for (qj, sj) in q.iter_mut().zip(&self.s[i]) {
                *qj += (alpha[i] - beta) * sj;
            }
        }
        q.iter_mut().for_each(|v| *v = -*v);
        q
    }

    /// One iteration: a direction, a line search, the update. Returns the
    /// objective's parts at the accepted point, or the stop reason if the
    /// run is over (then nothing changed).
    pub fn iterate<O: Objective>(
        &mut self,
        settings: &Settings,
        objective: &mut O,
    ) -> Result<Step<O::Parts>, O::Error> {
        if let Some(stop) = self.check(settings) {
            self.stopped = Some(stop);
            return Ok(Step::Stopped(stop));
        }
        let accepted = match settings.method {
            Method::Lbfgs { memory } => {
                let blocks = if settings.block_scaling { objective.blocks() } else { Vec::new() };
                let mut d = self.lbfgs_direction(&blocks, |v| objective.precondition(v));
                let mut slope = dot(&d, &self.grad);
                if slope >= 0.0 || !slope.is_finite() {
                    // Not a descent direction (should not happen with
                    // curvature-checked pairs): restart from −∇J.
                    self.s.clear();
                    self.y.clear();
                    d = self.lbfgs_direction(&blocks, |v| objective.precondition(v));
                    slope = dot(&d, &self.grad);
                }
                // Without pairs the direction is −M⁻¹∇J, unscaled: see
                // `first_step`; afterwards the scaled direction's natural
                // unit step.
                let t0 = if self.s.is_empty() { self.first_step(&d) } else { 1.0 };
                let found = wolfe_search(self, &d, slope, t0, settings, objective)?;
                if let Some((t, _, _, grad, _)) = &found {
                    let s: Vec<f64> = d.iter().map(|v| t * v).collect();
                    let y: Vec<f64> = grad.iter().zip(&self.grad).map(|(a, b)| a - b).collect();
                    // Keep the pair only with positive curvature (always
                    // true after a strong Wolfe step, kept as a guard).
                    if dot(&s, &y) > 0.0 {
                        if self.s.len() == memory {
                            self.s.pop_front();
                            self.y.pop_front();
                        }
                        self.s.push_back(s);
                        self.y.push_back(y);
                    }
                }
                found
            }
            Method::GradientDescent { increase } => {
                let mut d = self.grad.clone();
                objective.precondition(&mut d);
                d.iter_mut().for_each(|v| *v = -*v);
                let slope = dot(&d, &self.grad);
                let t0 = if self.step > 0.0 { self.step * increase } else { self.first_step(&d) };
                armijo_search(self, &d, slope, t0, settings, objective)?
            }
        };
        match accepted {
            Some((t, x, value, grad, parts)) => {
                self.x = x;
                self.value = value;
                self.grad = grad;
                self.step = t;
                self.iteration += 1;
                self.values.push(value);
                Ok(Step::Accepted(parts))
            }
            None => {
                self.stopped = Some(Stop::LineSearch);
                Ok(Step::Stopped(Stop::LineSearch))
            }
        }
    }

    /// Iterates until a stopping rule fires; `each` sees the state after
    /// every accepted step (progress, checkpoints).
    pub fn run<O: Objective>(
        &mut self,
        settings: &Settings,
        objective: &mut O,
        mut each: impl FnMut(&State),
    ) -> Result<Stop, O::Error> {
        loop {
            match self.iterate(settings, objective)? {
                Step::Stopped(stop) => return Ok(stop),
                Step::Accepted(_) => each(self),
            }
        }
    }
}

/// An accepted step: (t, x + t·d, J, ∇J, the objective's parts).
type Accepted<P> = Option<(f64, Vec<f64>, f64, Vec<f64>, P)>;

/// J, ∇J, φ'(t), the point x + t d and the objective's parts.
type Probe<P> = (f64, Vec<f64>, f64, Vec<f64>, P);

/// Evaluates φ(t) = J(x + t d): (J, ∇J, φ'(t), the point, the parts), with
/// non-finite values reported as `None` (treated as "too far").
fn probe<O: Objective>(
    state: &mut State,
    d: &[f64],
    t: f64,
    objective: &mut O,
) -> Result<Option<Probe<O::Parts>>, O::Error> {
    let x: Vec<f64> = state.x.iter().zip(d).map(|(a, b)| a + t * b).collect();
    state.evaluations += 1;
    let Evaluation { value, grad, parts } = objective.value_grad(&x)?;
    if !finite(value, &grad) {
        return Ok(None);
    }
    let slope = dot(&grad, d);
    Ok(Some((value, grad, slope, x, parts)))
}

const C1: f64 = 1e-4;
const C2: f64 = 0.9;

/// A step satisfying the strong Wolfe conditions along the descent
/// direction `d` (φ'(0) = `slope` < 0), starting from trial `t0`.
fn wolfe_search<O: Objective>(
    state: &mut State,
    d: &[f64],
    slope: f64,
    t0: f64,
    settings: &Settings,
    objective: &mut O,
) -> Result<Accepted<O::Parts>, O::Error> {
    let (f0, g0) = (state.value, slope);
    let mut budget = settings.max_evaluations_per_search;
    // Bracketing (N&W Algorithm 3.5). (t, φ, φ') of the previous trial.
    let mut prev = (0.0, f0, g0);
    let mut t = t0;
    let mut first = true;
    while budget > 0 {
        budget -= 1;
        let Some((f, grad, g, x, parts)) = probe(state, d, t, objective)? else {
            // Non-finite: the step went too far; shrink towards prev.
            t = 0.5 * (prev.0 + t);
            first = false;
            continue;
        };
        if f > f0 + C1 * t * g0 || (!first && f >= prev.1) {
            return zoom(state, d, (f0, g0), prev, (t, f, g), budget, objective);
        }
        if g.abs() <= -C2 * g0 {
            return Ok(Some((t, x, f, grad, parts)));
        }
        if g >= 0.0 {
            return zoom(state, d, (f0, g0), (t, f, g), prev, budget, objective);
        }
        prev = (t, f, g);
        t *= 2.0;
        first = false;
    }
    Ok(None)
}

/// The zoom phase (N&W Algorithm 3.6) between `lo` (the lowest φ so far,
/// satisfying the sufficient decrease) and `hi`, by safeguarded cubic
/// interpolation.
fn zoom<O: Objective>(
    state: &mut State,
    d: &[f64],
    (f0, g0): (f64, f64),
    mut lo: (f64, f64, f64),
    mut hi: (f64, f64, f64),
    mut budget: usize,
    objective: &mut O,
) -> Result<Accepted<O::Parts>, O::Error> {
    // The point, gradient and parts of `lo` once a probe here has set it.
    let mut lo_point: Option<(Vec<f64>, Vec<f64>, O::Parts)> = None;
    while budget > 0 {
        budget -= 1;
        let t = cubic_min(lo, hi);
        if (t - lo.0).abs() <= f64::EPSILON * lo.0.abs().max(1e-300) {
            break;
        }
        let Some((f, grad, g, x, parts)) = probe(state, d, t, objective)? else {
            hi = (t, f64::INFINITY, 0.0);
            continue;
        };
        if f > f0 + C1 * t * g0 || f >= lo.1 {
            hi = (t, f, g);
        } else {
            if g.abs() <= -C2 * g0 {
                return Ok(Some((t, x, f, grad, parts)));
            }
            if g * (hi.0 - lo.0) >= 0.0 {
                hi = lo;
            }
            lo = (t, f, g);
            lo_point = Some((x, grad, parts));
        }
    }
    // Out of evaluations: accept the best point if it decreased J enough.
    if lo.0 > 0.0 && lo.1 <= f0 + C1 * lo.0 * g0 {
        // Re-evaluated only if `lo` came from the bracketing phase.
        if let Some((x, grad, parts)) = lo_point {
            return Ok(Some((lo.0, x, lo.1, grad, parts)));
        }
        let Some((f, grad, _, x, parts)) = probe(state, d, lo.0, objective)? else { return Ok(None) };
        return Ok(Some((lo.0, x, f, grad, parts)));
    }
    Ok(None)
}

/// The minimiser of the cubic through (a, φ_a, φ'_a) and (b, φ_b, φ'_b),
/// kept inside the middle 80 % of the interval (bisection if the cubic has
/// no usable minimiser there, or if φ_b is not finite).
fn cubic_min(a: (f64, f64, f64), b: (f64, f64, f64)) -> f64 {
    let (lo, hi) = (a.0.min(b.0), a.0.max(b.0));
    let mid = 0.5 * (a.0 + b.0);
    if !b.1.is_finite() {
        return mid;
    }
    let d1 = a.2 + b.2 - 3.0 * (a.1 - b.1) / (a.0 - b.0);
    let disc = d1 * d1 - a.2 * b.2;
    if disc < 0.0 {
        return mid;
    }
    let d2 = (b.0 - a.0).signum() * disc.sqrt();
    let t = b.0 - (b.0 - a.0) * (b.2 + d2 - d1) / (b.2 - a.2 + 2.0 * d2);
    let margin = 0.1 * (hi - lo);
    if t.is_finite() { t.clamp(lo + margin, hi - margin) } else { mid }
}

/// Backtracking (halving) from `t0` until the Armijo condition holds.
fn armijo_search<O: Objective>(
    state: &mut State,
    d: &[f64],
    slope: f64,
    t0: f64,
    settings: &Settings,
    objective: &mut O,
) -> Result<Accepted<O::Parts>, O::Error> {
    let f0 = state.value;
    let mut t = t0;
    for _ in 0..settings.max_evaluations_per_search {
        if let Some((f, grad, _, x, parts)) = probe(state, d, t, objective)?
            && f <= f0 + C1 * t * slope
        {
            return Ok(Some((t, x, f, grad, parts)));
        }
        t *= 0.5;
    }
    Ok(None)
}
