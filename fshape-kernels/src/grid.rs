//! The grid path: particle–mesh sums of Gaussians, whose cost grows
//! linearly with the points when the kernel is wide against their spacing.
//!
//! A Gaussian wider than the points' spacing makes every target feel every
//! source: the exact sum costs N·M and truncation cannot help. The grid
//! path replaces the kernel k by a kernel k̃ that is cheap to sum,
//!
//! ```text
//! k̃(x, y) = Σ_{g, g'} W(x − g) G(g − g') W(y − g'),
//! ```
//!
//! with g, g' the nodes of the lattice hℤ^d (origin 0, spacing h), W the
//! tensor product of centred cardinal B-splines of order p (degree p − 1)
//! and spacing h, and G a filter on the lattice. A sum Σ_j k̃(x_i, y_j) b_j
//! is three linear maps: spread the weights onto the nodes (M·p^d terms),
//! convolve with G, and interpolate back at the targets (N·p^d terms).
//! This is Deformetrica's P3M kernel, and smooth particle-mesh Ewald's and
//! NUFFT gridding's scheme.
//!
//! **One objective.** k̃ is a fixed function of (x, y): the lattice does
//! not move with the points (only the window of nodes that the points touch
//! is allocated, and it changes nothing in k̃). Every derivative here is
//! the exact derivative of k̃ — ∇W and ∇²W at the moving points, the same
//! filter — with respect to the targets, the sources and the weights, so a
//! gradient computed through the grid path is the exact gradient of the
//! approximate objective. W is C^{p−2}: p ≥ 4 makes the shooting's field,
//! which uses ∇W, continuously differentiable. G is even with a
//! non-negative transfer function, so k̃ is symmetric and positive
//! semi-definite like the Gaussian it replaces.
//!
//! **The filter.** In one dimension, with k̂(ξ) = σ√(2π) e^{−σ²ξ²/2} and
//! Ŵ(ξ) = h sinc(ξh/2)^p the Fourier transforms of the Gaussian and of
//! the B-spline, G's transfer function is Γ(ξ) = h k̂(ξ)/Ŵ(ξ)² on the band
//! |ξ| ≤ π/h (it undoes the B-spline's smoothing, as SPME's B-spline
//! moduli do). With z = ξh/2 and s = σ/h its taps are
//!
//! ```text
//! G_l = (2s√(2π)/π) ∫_0^{π/2} e^{−2s²z²} sinc(z)^{−2p} cos(2lz) dz,
//! ```
//!
//! computed by quadrature, their tail cut where it sums to at most 10⁻¹⁴. A
//! Gaussian is a product over the axes, so the d-dimensional filter is
//! the product of d one-dimensional ones and the convolution is d passes
//! of a one-dimensional filter along the lattice's lines. (An FFT would
//! cost n log n on the window instead of n·taps; at the spacings the error
//! budget asks for, the windows are a few dozen nodes wide and the direct
//! passes cost less than spreading and interpolating, measured in the
//! README's grid table.) A sum of Gaussians is one filter per term on
//! the same lattice, sharing the spreading and the interpolation.
//!
//! **The error bound.** By Poisson summation, in one dimension
//!
//! ```text
//! k̃(x, y) = (1/2π) ∫_{|ξ|≤π/h} k̂(ξ) Σ_{k,l} ρ_k ρ_l e^{i(ξ_k x − ξ_l y)} dξ,
//! ξ_k = ξ + 2πk/h,   ρ_k = Ŵ(ξ_k)/Ŵ(ξ),   |ρ_k| = |z/(z + πk)|^p,
//! ```
//!
//! whose k = l = 0 term is the Gaussian without its part beyond the band.
//! Hence, with S(z) = Σ_{k≠0} |z/(z + πk)|^p and T(z) = Σ_{k≠0}
//! |z|^p/|z + πk|^{p−1}, for every x and y
//!
//! ```text
//! |k̃ − k| ≤ E₀ = ∫_{−π/2}^{π/2} s√(2/π) e^{−2s²z²} (2S + S²) dz + erfc(πs/√2)
//! |∂_x k̃ − ∂_x k| ≤ E₁/(σ√e),
//! E₁ = ∫_{−π/2}^{π/2} s√(2/π) e^{−2s²z²} 2s√e (|z|S + T(1 + S)) dz + √(2e/π) e^{−π²s²/2}
//! ```
//!
//! (1/(σ√e) is the largest |k'| of the unit Gaussian), plus the cut taps'
//! sum (Σ_n W = 1 and Σ_n |∂W| ≤ 2/h bound what they carry). In d
//! dimensions k̃ is the product of the axes' factors, so a Gaussian term
//! of weight w is within w((1 + E₀)^d − 1) and its gradient within
//! w(E₁(1 + E₀)^{d−1} + (1 + E₀)^{d−1} − 1)/(σ√e). Per output:
//! |out_i − exact_i| ≤ ε·k(0)·Σ_j |b_j|, the form of the truncation's
//! bound, with ε = [`GridBound::value`]. The bound falls like (h/σ)^p for
//! small h/σ; [`crate::Kernel::grid_spacing`] inverts it for a tolerance.
//!
//! **Determinism.** Spreading is split into slabs of lattice planes, each
//! visiting the sources in increasing order, so every node sums its
//! contributions in source order whatever the number of slabs; each
//! convolution output and each target sums in a fixed order. Serial and
//! parallel results are equal bit for bit.

// Index loops over the stencil's nodes and the channels are the shape of
// the formulas (and of what the compiler unrolls).
#![expect(clippy::needless_range_loop, reason = "stencil and channel loops follow the formulas")]

use rayon::prelude::*;

use crate::KernelError;
use crate::taper::GaussTerms;

/// The B-spline orders the grid path takes: even, so that a point's nodes
/// sit symmetrically about it, and at least 4, so that the field of a
/// shooting, which uses ∇W, is continuously differentiable (W is
/// C^{p−2}).
pub const GRID_ORDERS: [usize; 3] = [4, 6, 8];

/// The most weight components a grid sum takes per point.
const MAX_CHANNELS: usize = 4;

/// The most lattice nodes (times weight components) a grid sum allocates:
/// 2²⁸ values, 2 GiB per array.
const MAX_VALUES: usize = 1 << 28;

/// A filter's tail is cut where the taps beyond sum (both sides) to at
/// most this (for a unit Gaussian; the cut is added to the bound).
const TAP_CUT: f64 = 1e-14;

/// Quadrature intervals on [0, π/2] (composite Simpson) for the taps and
/// the bound.
const QUADRATURE: usize = 4096;

/// Aliases |k| ≤ this are summed in S and T; the rest is bounded in
/// closed form.
const ALIASES: usize = 64;

/// The grid approximation of a sum of Gaussians: lattice spacing h,
/// B-spline order p, and one filter per Gaussian term.
#[derive(Clone, Debug)]
pub struct Grid {
    spacing: f64,
    order: usize,
    /// One-sided taps G_0, G_1, … of each term's filter, for the unit
    /// Gaussian (the term's weight is applied after the convolution).
    taps: std::sync::Arc<[Vec<f64>]>,
    bound: GridBound,
    basis: std::sync::Arc<Basis>,
}

impl PartialEq for Grid {
    fn eq(&self, other: &Self) -> bool {
        // The taps and the bound follow from the rest of the kernel.
        self.spacing == other.spacing && self.order == other.order
    }
}

/// The grid path's error bounds, relative (module docs): for every x, y,
/// |k̃(x, y) − k(|x − y|²)| ≤ `value`·k(0), and each component of
/// ∇_x k̃ − ∇_x k is within `gradient`·Σ_t w_t/(σ_t√e) (for one Gaussian,
/// `gradient` times its largest slope). Per output of a sum:
/// |out_i − exact_i| ≤ value·k(0)·Σ_j |b_j|.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridBound {
    /// Bound on the kernel's values, relative to k(0).
    pub value: f64,
    /// Bound on the kernel's gradient, relative to Σ_t w_t/(σ_t√e).
    pub gradient: f64,
}

impl Grid {
    /// The grid of `terms` (a sum of Gaussians) with spacing `h` and order
    /// `p` in `dim` dimensions; the arguments were checked by the caller.
    pub(crate) fn new(terms: &GaussTerms, h: f64, p: usize, dim: usize) -> Grid {
        let tables = AliasTables::new(p);
        let mut taps = Vec::with_capacity(terms.n);
        let (mut value, mut gradient, mut slopes) = (0.0, 0.0, 0.0);
        let mut k0 = 0.0;
        for t in 0..terms.n {
            let (a, w) = (terms.a[t], terms.w[t]);
            let sigma = (0.5 / a).sqrt();
            let s = sigma / h;
            let (g, cut) = filter(s, p);
            let (v, g1) = tables.worst(s, cut, dim);
            let slope = 1.0 / (sigma * std::f64::consts::E.sqrt());
            value += w * v;
            gradient += w * g1 * slope;
            slopes += w * slope;
            k0 += w;
            taps.push(g);
        }
        Grid {
            spacing: h,
            order: p,
            basis: std::sync::Arc::new(Basis::new(p, h)),
            taps: taps.into(),
            bound: GridBound { value: value / k0, gradient: gradient / slopes },
        }
    }

    /// The lattice spacing h.
    pub fn spacing(&self) -> f64 {
        self.spacing
    }

    /// The B-spline order p.
    pub fn order(&self) -> usize {
        self.order
    }

    /// The error bound (module docs).
    pub fn bound(&self) -> GridBound {
        self.bound
    }

    /// The largest number of taps on one side of a filter.
    pub fn taps(&self) -> usize {
        self.taps.iter().map(Vec::len).max().unwrap_or(0)
    }

    /// The number of Gaussian terms (one filter each).
    pub fn n_terms(&self) -> usize {
        self.taps.len()
    }
}

/// The one-sided taps G_0, G_1, … of the filter of a unit Gaussian with
/// s = σ/h and order p (module docs), cut below [`TAP_CUT`]·G_0, and the
/// sum of the cut ones (both sides) as far as they were computed.
fn filter(s: f64, p: usize) -> (Vec<f64>, f64) {
    use std::f64::consts::PI;
    let half = PI / 2.0;
    let m = QUADRATURE;
    let dz = half / m as f64;
    // Simpson weights times the integrand at each node.
    let f: Vec<f64> = (0..=m)
        .map(|q| {
            let z = q as f64 * dz;
            let simpson = if q == 0 || q == m {
                1.0
            } else if q % 2 == 1 {
                4.0
            } else {
                2.0
            };
            let sinc = if z == 0.0 { 1.0 } else { z.sin() / z };
            simpson * dz / 3.0 * (-2.0 * s * s * z * z).exp() / sinc.powi(2 * p as i32)
        })
        .collect();
    let scale = 2.0 * s * (2.0 * PI).sqrt() / PI;
    let tap =
        |l: usize| scale * f.iter().enumerate().map(|(q, v)| v * (2.0 * l as f64 * q as f64 * dz).cos()).sum::<f64>();
    // The taps fall like the sampled Gaussian e^{−l²/(2s²)}, then like the
    // band edge's small kink (~Γ(π/h)/l²): compute well past 9s and cut.
    // Beyond the last computed tap the kink's tail is below 1e-16 at the
    // spacings a tolerance asks for.
    let last = (12.0 * s).ceil() as usize + 4 * p + 16;
    let all: Vec<f64> = (0..=last).map(tap).collect();
    // The longest tail whose taps sum to at most TAP_CUT.
    let mut keep = all.len();
    let mut cut = 0.0;
    while keep > 1 && cut + 2.0 * all[keep - 1].abs() <= TAP_CUT {
        keep -= 1;
        cut += 2.0 * all[keep].abs();
    }
    (all[..keep].to_vec(), cut)
}

/// S(z) and T(z) (module docs) on the quadrature nodes of [0, π/2], for
/// one order: they do not depend on h/σ, so a bound for any s is one
/// weighted sum over the nodes.
struct AliasTables {
    s: Vec<f64>,
    t: Vec<f64>,
}

impl AliasTables {
    fn new(p: usize) -> AliasTables {
        use std::f64::consts::PI;
        let m = QUADRATURE;
        let dz = PI / 2.0 / m as f64;
        let (mut s, mut t) = (Vec::with_capacity(m + 1), Vec::with_capacity(m + 1));
        let (pi, pf) = (p as i32, p as f64);
        // Σ_{k>K} 1/(π(k − ½))^q ≤ 1/(π^q (q − 1)(K − ½)^{q−1}), both signs.
        let tail = |q: f64| 2.0 / (PI.powf(q) * (q - 1.0) * (ALIASES as f64 - 0.5).powf(q - 1.0));
        for q in 0..=m {
            let z = q as f64 * dz;
            let (mut ss, mut tt) = (0.0, 0.0);
            for k in 1..=ALIASES {
                for shift in [PI * k as f64, -PI * k as f64] {
                    let d = (z + shift).abs();
                    ss += (z / d).powi(pi);
                    tt += z.powi(pi) / d.powi(pi - 1);
                }
            }
            s.push(ss + z.powi(pi) * tail(pf));
            t.push(tt + z.powi(pi) * tail(pf - 1.0));
        }
        AliasTables { s, t }
    }

    /// The d-dimensional bounds of a unit Gaussian for s = σ/h with the cut
    /// taps' sum `cut`: on the value, (1 + E₀)^d − 1, and on the gradient
    /// relative to 1/(σ√e), E₁(1 + E₀)^{d−1} + (1 + E₀)^{d−1} − 1. The cut
    /// taps add `cut` to E₀ (Σ_n W = 1) and 2s√e·`cut` to E₁ (Σ_n |∂W| ≤ 2/h).
    fn worst(&self, s: f64, cut: f64, dim: usize) -> (f64, f64) {
        let (e0, e1) = self.bound(s);
        let e0 = e0 + cut;
        let e1 = e1 + 2.0 * s * std::f64::consts::E.sqrt() * cut;
        let grow = (1.0 + e0).powi(dim as i32 - 1);
        ((1.0 + e0) * grow - 1.0, e1 * grow + grow - 1.0)
    }

    /// (E₀, E₁) for s = σ/h (module docs), without the cut taps.
    fn bound(&self, s: f64) -> (f64, f64) {
        use std::f64::consts::{E, PI};
        let m = QUADRATURE;
        let dz = PI / 2.0 / m as f64;
        let (mut e0, mut e1) = (0.0, 0.0);
        for q in 0..=m {
            let z = q as f64 * dz;
            let simpson = if q == 0 || q == m {
                1.0
            } else if q % 2 == 1 {
                4.0
            } else {
                2.0
            };
            // Both halves of the symmetric integrand: twice [0, π/2].
            let density = 2.0 * simpson * dz / 3.0 * s * (2.0 / PI).sqrt() * (-2.0 * s * s * z * z).exp();
            let (ss, tt) = (self.s[q], self.t[q]);
            e0 += density * (2.0 * ss + ss * ss);
            e1 += density * 2.0 * s * E.sqrt() * (z * ss + tt * (1.0 + ss));
        }
        let x = PI * s / 2f64.sqrt();
        (e0 + erfc(x), e1 + (2.0 * E / PI).sqrt() * (-x * x).exp())
    }
}

/// The complementary error function, for x ≥ 0, to about 1e-7 relative
/// (Numerical Recipes' erfcc, Chebyshev fit): the bound's out-of-band tail.
fn erfc(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.5 * x.abs());
    let poly = -x * x - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98 + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    // The fit's relative error is below 1.2e-7: round the bound up.
    t * poly.exp() * (1.0 + 1.2e-7)
}

/// How much larger than the tolerance the grid path's gradient bound may
/// be. A truncated kernel's gradient error is larger than its value error
/// by about this much (its taper's slope: up to 13.5τ relative to the
/// largest slope at τ = 1e-6), and the gradient bound of the grid path
/// falls one power of h/σ slower than its value bound: asking both for τ
/// would make the grid finer than truncation is accurate.
pub const GRADIENT_SLACK: f64 = 10.0;

/// The smallest s = σ/h (largest spacing) at which a unit Gaussian's
/// bounds in `dim` dimensions (cut taps included) are within `tol` for
/// the value and [`GRADIENT_SLACK`]·`tol` for the gradient, for order `p`
/// (at most 64: a finer lattice is never worth it).
pub(crate) fn ratio_for(tol: f64, p: usize, dim: usize) -> f64 {
    let tables = AliasTables::new(p);
    let worst = |s: f64| {
        let (v, g) = tables.worst(s, filter(s, p).1, dim);
        (v / tol).max(g / (GRADIENT_SLACK * tol))
    };
    let (mut lo, mut hi) = (0.25, 1.0);
    while worst(hi) > 1.0 && hi < 64.0 {
        hi *= 2.0;
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if worst(mid) > 1.0 { lo = mid } else { hi = mid }
    }
    // The cut taps add at most ~1e-15 of the central tap: a small margin.
    hi * 1.001
}

/// One point's B-spline stencil along one axis: the first node's index and
/// the weights of the P nodes from it, with their first and second
/// derivatives in the coordinate.
#[derive(Clone, Copy)]
struct Axis<const P: usize> {
    first: i64,
    w: [f64; P],
    dw: [f64; P],
    ddw: [f64; P],
}

impl<const P: usize> Axis<P> {
    /// The trivial axis of a planar problem (one node, weight 1).
    fn flat() -> Axis<P> {
        let mut w = [0.0; P];
        w[0] = 1.0;
        Axis { first: 0, w, dw: [0.0; P], ddw: [0.0; P] }
    }

    /// The index of the first node of coordinate `x`'s stencil.
    #[inline(always)]
    fn first(x: f64, h: f64) -> i64 {
        floor(x / h - 0.5 * P as f64) + 1
    }

    /// The stencil of coordinate `x` on the lattice of spacing `h`: with
    /// v = x/h − P/2 and t = v − ⌊v⌋, node ⌊v⌋ + 1 + k has weight
    /// N_P(t + P − 1 − k), N_P the cardinal B-spline on [0, P], a polynomial
    /// in t on each piece: `basis` holds the coefficients ([`Basis`]), and
    /// each weight and derivative is one Horner evaluation, P lanes wide.
    #[inline(always)]
    fn of(x: f64, h: f64, basis: &Basis) -> Axis<P> {
        let v = x / h - 0.5 * P as f64;
        let fl = floor(v);
        let t = v - fl as f64;
        let mut out = Axis { first: fl + 1, w: [0.0; P], dw: [0.0; P], ddw: [0.0; P] };
        for j in (0..P).rev() {
            for k in 0..P {
                out.w[k] = out.w[k] * t + basis.c[0][j][k];
                out.dw[k] = out.dw[k] * t + basis.c[1][j][k];
                out.ddw[k] = out.ddw[k] * t + basis.c[2][j][k];
            }
        }
        out
    }
}

/// The B-spline weights of order p as polynomials in the fractional
/// position t ∈ [0, 1): `c[d][j][k]` is the coefficient of t^j in the d-th
/// derivative (in x, so divided by h^d) of node k's weight N_p(t + p − 1 −
/// k). Built once per grid by running the Cox–de Boor recursion
/// N_q(u) = (u N_{q−1}(u) + (q − u) N_{q−1}(u − 1))/(q − 1) on the pieces'
/// coefficients.
#[derive(Clone, Debug)]
pub(crate) struct Basis {
    c: [[[f64; 8]; 8]; 3],
}

impl Basis {
    pub(crate) fn new(p: usize, h: f64) -> Basis {
        // pieces[m][j]: the coefficient of t^j in N_q(t + m), m < q.
        let mut pieces = vec![vec![1.0f64]];
        for q in 2..=p {
            let qf = q as f64;
            let zero = vec![0.0; q - 1];
            let next: Vec<Vec<f64>> = (0..q)
                .map(|m| {
                    let mf = m as f64;
                    let left = if m > 0 { &pieces[m - 1] } else { &zero };
                    let here = pieces.get(m).unwrap_or(&zero);
                    let mut c = vec![0.0; q];
                    for j in 0..q - 1 {
                        // (t + m)·here + (q − m − t)·left, then / (q − 1).
                        c[j] += mf * here[j] + (qf - mf) * left[j];
                        c[j + 1] += here[j] - left[j];
                    }
                    c.iter().map(|v| v / (qf - 1.0)).collect()
                })
                .collect();
            pieces = next;
        }
        let mut c = [[[0.0; 8]; 8]; 3];
        for k in 0..p {
            let piece = &pieces[p - 1 - k];
            for j in 0..p {
                c[0][j][k] = piece[j];
                if j >= 1 {
                    c[1][j - 1][k] = j as f64 * piece[j] / h;
                }
                if j >= 2 {
                    c[2][j - 2][k] = (j * (j - 1)) as f64 * piece[j] / (h * h);
                }
            }
        }
        Basis { c }
    }
}

/// ⌊v⌋ for |v| < 2⁵³ (the window's check keeps coordinates far below):
/// a cast and a correction, where `f64::floor` is a library call on
/// x86-64 without SSE4.1.
#[inline(always)]
fn floor(v: f64) -> i64 {
    let i = v as i64;
    if (i as f64) > v { i - 1 } else { i }
}

/// The window of lattice nodes a sum touches: the first node and the
/// number of nodes along each axis (axis 0 fastest in memory; a planar
/// problem has one node along axis 2).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Window {
    lo: [i64; 3],
    n: [usize; 3],
}

impl Window {
    fn nodes(&self) -> usize {
        self.n[0] * self.n[1] * self.n[2]
    }
}

/// A point's stencils along the real axes (the third is flat in 2-D).
#[inline(always)]
fn stencil<const D: usize, const P: usize>(x: &[f64], h: f64, basis: &Basis) -> [Axis<P>; 3] {
    let mut s = [Axis::flat(), Axis::flat(), Axis::flat()];
    for a in 0..D {
        s[a] = Axis::of(x[a], h, basis);
    }
    s
}

/// Memory the grid sums reuse from call to call.
#[derive(Default)]
pub(crate) struct GridWorkspace {
    /// The spread weights and their directional derivative (node-major,
    /// channels interleaved), and the convolved fields (channel-major).
    spread: Vec<f64>,
    dspread: Vec<f64>,
    phi: Vec<f64>,
    dphi: Vec<f64>,
    tmp: [Vec<f64>; 2],
    /// Run the spreading and gathering without SIMD dispatch (baseline
    /// x86-64), for the test that every instruction set gives the same bits.
    #[cfg(test)]
    scalar: bool,
}

/// Runs `op` compiled for the CPU's vector width, or for baseline x86-64
/// when `scalar` (tests only).
#[inline(always)]
fn dispatch<W: pulp::WithSimd>(arch: pulp::Arch, scalar: bool, op: W) -> W::Output {
    if scalar { op.with_simd(pulp::Scalar::new()) } else { arch.dispatch(op) }
}

// What a grid sum computes, and its inputs: the modes and inputs of `fast.rs`.
use crate::fast::{BOTH_JVP, CONV, CONV_GRAD, CONV_JVP, GRAD_JVP, Inputs};

/// Computes the sum `MODE` of the grid kernel into `out1` (the first
/// `split` values of each target's row) and `out2` (the rest). Fails
/// when the points spread over more lattice nodes than [`MAX_VALUES`].
#[allow(clippy::too_many_arguments)]
pub(crate) fn grid_sum_into<const MODE: u8>(
    grid: &Grid,
    terms: &GaussTerms,
    inp: Inputs<'_>,
    dim: usize,
    bdim: usize,
    parallel: bool,
    ws: &mut GridWorkspace,
    split: usize,
    out1: &mut [f64],
    out2: &mut [f64],
) -> Result<(), KernelError> {
    if !(1..=MAX_CHANNELS).contains(&bdim) {
        return Err(KernelError::GridChannels { found: bdim, max: MAX_CHANNELS });
    }
    #[cfg(test)]
    let scalar = ws.scalar;
    #[cfg(not(test))]
    let scalar = false;
    let job = Job { grid, terms, inp, c: bdim, parallel, scalar, split };
    match (dim, grid.order) {
        (2, 4) => job.run::<2, 4, MODE>(ws, out1, out2),
        (2, 6) => job.run::<2, 6, MODE>(ws, out1, out2),
        (2, 8) => job.run::<2, 8, MODE>(ws, out1, out2),
        (3, 4) => job.run::<3, 4, MODE>(ws, out1, out2),
        (3, 6) => job.run::<3, 6, MODE>(ws, out1, out2),
        (3, 8) => job.run::<3, 8, MODE>(ws, out1, out2),
        (2 | 3, order) => Err(KernelError::GridOrder { order }),
        _ => Err(KernelError::PointDimension { found: dim }),
    }
}

/// One grid sum: what it computes and with what.
struct Job<'a> {
    grid: &'a Grid,
    terms: &'a GaussTerms,
    inp: Inputs<'a>,
    /// Weight components per point.
    c: usize,
    parallel: bool,
    /// Baseline x86-64 instead of the dispatched vector code (tests).
    scalar: bool,
    /// Values of each target's row that go to the first output.
    split: usize,
}

impl Job<'_> {
    fn run<const D: usize, const P: usize, const MODE: u8>(
        &self,
        ws: &mut GridWorkspace,
        out1: &mut [f64],
        out2: &mut [f64],
    ) -> Result<(), KernelError> {
        let (h, c, inp) = (self.grid.spacing, self.c, &self.inp);
        let basis = &*self.grid.basis;
        let win = window::<D, P>(&[inp.x, inp.y], h)?;
        if win.nodes() * c > MAX_VALUES {
            return Err(KernelError::GridTooLarge { nodes: win.nodes(), spacing: h });
        }
        let jvp = MODE == CONV_JVP || MODE == GRAD_JVP || MODE == BOTH_JVP;
        let scalar = self.scalar;
        let GridWorkspace { spread: s, dspread: ds, phi, dphi, tmp, .. } = ws;
        let par = (self.parallel, scalar);
        spread::<D, P>(inp.y, inp.b, None, c, (h, basis), &win, par, s);
        self.convolve(D, &win, s, tmp, phi);
        if jvp {
            spread::<D, P>(inp.y, inp.b, Some((inp.dy, inp.db)), c, (h, basis), &win, par, ds);
            self.convolve(D, &win, ds, tmp, dphi);
        }
        let fields = Fields { phi: &phi[..], dphi: if jvp { &dphi[..] } else { &[] }, win, c };
        let rows = crate::fast::rows(MODE, D, c);
        let (split, w2) = (self.split, rows - self.split);
        // Chunks of targets, each compiled for the CPU's vector width.
        let arch = crate::simd::arch();
        let chunk = |(k, (o1, o2)): (usize, (&mut [f64], &mut [f64]))| {
            let first = k * GATHER_CHUNK;
            dispatch(arch, scalar, Gather::<D, P, MODE> { fields: &fields, inp, h, basis, first, rows, split, o1, o2 })
        };
        if w2 == 0 {
            let single = |(k, o1): (usize, &mut [f64])| chunk((k, (o1, &mut [])));
            if self.parallel {
                out1.par_chunks_mut(split * GATHER_CHUNK).enumerate().for_each(single);
            } else {
                out1.chunks_mut(split * GATHER_CHUNK).enumerate().for_each(single);
            }
        } else if self.parallel {
            let pairs = out1.par_chunks_mut(split * GATHER_CHUNK).zip(out2.par_chunks_mut(w2 * GATHER_CHUNK));
            pairs.enumerate().for_each(chunk);
        } else {
            out1.chunks_mut(split * GATHER_CHUNK).zip(out2.chunks_mut(w2 * GATHER_CHUNK)).enumerate().for_each(chunk);
        }
        Ok(())
    }

    /// out = Σ_t w_t (G_t ⊗ … ⊗ G_t) * s over the window, one axis at a
    /// time through `tmp`: `s` node-major (channels interleaved), `out`
    /// channel-major.
    fn convolve(&self, dim: usize, win: &Window, s: &[f64], tmp: &mut [Vec<f64>; 2], out: &mut Vec<f64>) {
        out.clear();
        out.resize(s.len(), 0.0);
        for (t, taps) in self.grid.taps.iter().enumerate().take(self.terms.n) {
            let w = self.terms.w[t];
            let [t0, t1] = tmp;
            let par = (self.parallel, self.scalar);
            first_pass(taps, win, self.c, par, s, t0);
            axis_pass(taps, win, self.c, 1, par, t0, t1);
            let last = if dim == 3 {
                axis_pass(taps, win, self.c, 2, par, t1, t0);
                &*t0
            } else {
                &*t1
            };
            for (o, v) in out.iter_mut().zip(last) {
                *o += w * v;
            }
        }
    }
}

/// The window of nodes touched by every point of `sets`.
fn window<const D: usize, const P: usize>(sets: &[&[f64]], h: f64) -> Result<Window, KernelError> {
    let mut lo = [i64::MAX; 3];
    let mut hi = [i64::MIN; 3];
    for set in sets {
        for x in set.chunks_exact(D) {
            for a in 0..D {
                let v = (x[a] / h - 0.5 * P as f64).floor();
                if v.is_nan() || v.abs() >= 1e15 {
                    return Err(KernelError::GridTooLarge { nodes: usize::MAX, spacing: h });
                }
                let first = v as i64 + 1;
                lo[a] = lo[a].min(first);
                hi[a] = hi[a].max(first + P as i64);
            }
        }
    }
    let mut n = [1usize; 3];
    for a in 0..3 {
        if a >= D || lo[a] > hi[a] {
            lo[a] = 0;
            hi[a] = 1;
        }
        n[a] = (hi[a] - lo[a]) as usize;
    }
    if n.iter().try_fold(1usize, |acc, &v| acc.checked_mul(v)).is_none_or(|v| v > MAX_VALUES) {
        return Err(KernelError::GridTooLarge { nodes: usize::MAX, spacing: h });
    }
    Ok(Window { lo, n })
}

/// Spreads the weights `b` (M × c) at the sources `y` onto the window's
/// nodes: out[g] = Σ_j W(y_j − g) b_j, or with `d = (dy, db)` its
/// directional derivative Σ_j [(∇W(y_j − g)·dy_j) b_j + W(y_j − g) db_j],
/// node-major with the channels interleaved. The slowest axis is cut into
/// slabs spread in parallel; within a slab the sources are visited in
/// order, so each node's sum is in source order whatever the slabs.
#[allow(clippy::too_many_arguments)]
fn spread<const D: usize, const P: usize>(
    y: &[f64],
    b: &[f64],
    d: Option<(&[f64], &[f64])>,
    c: usize,
    lattice: (f64, &Basis),
    win: &Window,
    (parallel, scalar): (bool, bool),
    out: &mut Vec<f64>,
) {
    match (c, d.is_some()) {
        (1, false) => spread_c::<D, P, 1, false>(y, b, d, lattice, win, (parallel, scalar), out),
        (2, false) => spread_c::<D, P, 2, false>(y, b, d, lattice, win, (parallel, scalar), out),
        (3, false) => spread_c::<D, P, 3, false>(y, b, d, lattice, win, (parallel, scalar), out),
        (_, false) => spread_c::<D, P, 4, false>(y, b, d, lattice, win, (parallel, scalar), out),
        (1, true) => spread_c::<D, P, 1, true>(y, b, d, lattice, win, (parallel, scalar), out),
        (2, true) => spread_c::<D, P, 2, true>(y, b, d, lattice, win, (parallel, scalar), out),
        (3, true) => spread_c::<D, P, 3, true>(y, b, d, lattice, win, (parallel, scalar), out),
        (_, true) => spread_c::<D, P, 4, true>(y, b, d, lattice, win, (parallel, scalar), out),
    }
}

/// [`spread`] with `C` channels (`JVP`: `d` is `Some`).
fn spread_c<const D: usize, const P: usize, const C: usize, const JVP: bool>(
    y: &[f64],
    b: &[f64],
    d: Option<(&[f64], &[f64])>,
    (h, basis): (f64, &Basis),
    win: &Window,
    (parallel, scalar): (bool, bool),
    out: &mut Vec<f64>,
) {
    let slow = D - 1;
    let plane = win.nodes() / win.n[slow] * C;
    out.clear();
    out.resize(win.nodes() * C, 0.0);
    // Few slabs: a point whose stencil crosses k slabs is visited k times.
    let slabs = if parallel { (2 * rayon::current_num_threads()).min(win.n[slow]).max(1) } else { 1 };
    let per = win.n[slow].div_ceil(slabs);
    let (dy, db) = d.unwrap_or((&[], &[]));
    let arch = crate::simd::arch();
    let slab = |(k, chunk): (usize, &mut [f64])| {
        let z0 = (k * per) as i64 + win.lo[slow];
        let z1 = z0 + (chunk.len() / plane) as i64;
        dispatch(arch, scalar, Slab::<D, P, C, JVP> { y, b, dy, db, h, basis, win, z: (z0, z1), chunk });
    };
    if parallel {
        out.par_chunks_mut(per * plane).enumerate().for_each(slab);
    } else {
        out.chunks_mut(per * plane).enumerate().for_each(slab);
    }
}

/// One slab of the spreading, compiled for the CPU's vector width.
struct Slab<'a, const D: usize, const P: usize, const C: usize, const JVP: bool> {
    y: &'a [f64],
    b: &'a [f64],
    dy: &'a [f64],
    db: &'a [f64],
    h: f64,
    basis: &'a Basis,
    win: &'a Window,
    z: (i64, i64),
    chunk: &'a mut [f64],
}

impl<const D: usize, const P: usize, const C: usize, const JVP: bool> pulp::WithSimd for Slab<'_, D, P, C, JVP> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let Slab { y, b, dy, db, h, basis, win, z: (z0, z1), chunk } = self;
        let slow = D - 1;
        for (j, yj) in y.chunks_exact(D).enumerate() {
            // The stencil's range along the slab axis, before the whole stencil.
            let first = Axis::<P>::first(yj[slow], h);
            if first >= z1 || first + P as i64 <= z0 {
                continue;
            }
            let st = stencil::<D, P>(yj, h, basis);
            let bj: &[f64; C] = b[j * C..(j + 1) * C].try_into().expect("C values");
            if JVP {
                let dbj: &[f64; C] = db[j * C..(j + 1) * C].try_into().expect("C values");
                add_point::<D, P, C, true>(&st, bj, &dy[j * D..(j + 1) * D], dbj, win, (z0, z1), chunk);
            } else {
                add_point::<D, P, C, false>(&st, bj, &[], bj, win, (z0, z1), chunk);
            }
        }
    }
}

/// One source's contribution to the nodes of the slab [z0, z1) of the
/// slowest axis (`chunk` holds the slab's nodes); with `JVP`, that of its
/// directional derivative (`dyj`, `dbj`). Each row of P nodes along axis 0
/// gets a multiple of the same P·C products (two with `JVP`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn add_point<const D: usize, const P: usize, const C: usize, const JVP: bool>(
    st: &[Axis<P>; 3],
    bj: &[f64; C],
    dyj: &[f64],
    dbj: &[f64; C],
    win: &Window,
    (z0, z1): (i64, i64),
    chunk: &mut [f64],
) {
    let (nx, ny) = (win.n[0], win.n[1]);
    let x0 = (st[0].first - win.lo[0]) as usize;
    // Along axis 0: w_x b (and with JVP, w_x' dy_x b + w_x db).
    let (mut wb, mut dwb) = ([0.0f64; 32], [0.0f64; 32]);
    for kx in 0..P {
        for ch in 0..C {
            wb[kx * C + ch] = st[0].w[kx] * bj[ch];
            if JVP {
                dwb[kx * C + ch] = st[0].dw[kx] * dyj[0] * bj[ch] + st[0].w[kx] * dbj[ch];
            }
        }
    }
    // The stencil's part inside the slab, along the slab axis.
    let (slab_axis, pz) = if D == 3 { (2, P) } else { (1, 1) };
    let lo = (z0 - st[slab_axis].first).max(0) as usize;
    let hi = ((z1 - st[slab_axis].first).min(P as i64)) as usize;
    let (kz_range, ky_range) = if D == 3 { (lo..hi, 0..P) } else { (0..pz, lo..hi) };
    for kz in kz_range {
        for ky in ky_range.clone() {
            let (gz, gy) = (st[2].first + kz as i64, st[1].first + ky as i64);
            let row = if D == 3 {
                ((gz - z0) as usize * ny + (gy - win.lo[1]) as usize) * nx + x0
            } else {
                (gy - z0) as usize * nx + x0
            };
            let cells = &mut chunk[row * C..(row + P) * C];
            let wyz = st[2].w[kz] * st[1].w[ky];
            if JVP {
                // The directional derivative's y and z parts, times w_x b.
                let mut dyz = st[2].w[kz] * st[1].dw[ky] * dyj[1];
                if D == 3 {
                    dyz += st[2].dw[kz] * st[1].w[ky] * dyj[2];
                }
                for (i, cell) in cells.iter_mut().enumerate() {
                    *cell += wyz * dwb[i] + dyz * wb[i];
                }
            } else {
                for (i, cell) in cells.iter_mut().enumerate() {
                    *cell += wyz * wb[i];
                }
            }
        }
    }
}

/// The first axis of the separable convolution, which also turns the
/// node-major spread weights `input` into channel-major rows:
/// out[ch][…, i] = Σ_{i'} G_{|i − i'|} input[(…, i') · c + ch], each output
/// summed over i' in increasing order.
fn first_pass(
    taps: &[f64],
    win: &Window,
    c: usize,
    (parallel, scalar): (bool, bool),
    input: &[f64],
    out: &mut Vec<f64>,
) {
    let (nx, nodes) = (win.n[0], win.nodes());
    out.clear();
    out.resize(input.len(), 0.0);
    // The filter both ways, full[reach + d] = G_{|d|}: for one input node,
    // its contributions to consecutive outputs are consecutive taps.
    let reach = taps.len() - 1;
    let full: Vec<f64> = (0..2 * reach + 1).map(|k| taps[k.abs_diff(reach)]).collect();
    let arch = crate::simd::arch();
    let line = |(r, o): (usize, &mut [f64])| {
        let (ch, start) = (r / (nodes / nx), (r % (nodes / nx)) * nx);
        let input = &input[start * c..(start + nx) * c];
        dispatch(arch, scalar, FirstLine { full: &full, reach, input, c, ch, o });
    };
    if parallel {
        out.par_chunks_mut(nx).enumerate().with_min_len((1024 / nx).max(1)).for_each(line);
    } else {
        out.chunks_mut(nx).enumerate().for_each(line);
    }
}

/// One line of [`first_pass`]: channel `ch` of the node-major `input`.
/// Each output sums its inputs in increasing order.
struct FirstLine<'a> {
    full: &'a [f64],
    reach: usize,
    input: &'a [f64],
    c: usize,
    ch: usize,
    o: &'a mut [f64],
}

impl pulp::WithSimd for FirstLine<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let FirstLine { full, reach, input, c, ch, o } = self;
        let nx = o.len();
        o.fill(0.0);
        for i2 in 0..nx {
            let v = input[i2 * c + ch];
            // Outputs i with |i − i2| ≤ reach take full[reach + i − i2].
            let (from, to) = (i2.saturating_sub(reach), (i2 + reach + 1).min(nx));
            let taps = &full[reach + from - i2..reach + to - i2];
            for (ov, g) in o[from..to].iter_mut().zip(taps) {
                *ov += g * v;
            }
        }
    }
}

/// Axis 1 or 2 of the separable convolution on channel-major values:
/// out[…, i, …] = Σ_{i'} G_{|i − i'|} in[…, i', …], each output row summed
/// over i' in increasing order.
fn axis_pass(
    taps: &[f64],
    win: &Window,
    c: usize,
    axis: usize,
    (parallel, scalar): (bool, bool),
    input: &[f64],
    out: &mut Vec<f64>,
) {
    let len = win.n[axis];
    // Values per index along the axis (the faster axes).
    let inner: usize = win.n[..axis].iter().product::<usize>();
    debug_assert_eq!(input.len(), win.nodes() * c);
    out.clear();
    out.resize(input.len(), 0.0);
    let arch = crate::simd::arch();
    let row = |(r, o): (usize, &mut [f64])| {
        // The channel and the slower axes are the row's "outer" index.
        let (outer, i) = (r / len, r % len);
        let block = &input[outer * len * inner..(outer + 1) * len * inner];
        dispatch(arch, scalar, AxisRow { taps, block, inner, i, o });
    };
    if parallel {
        out.par_chunks_mut(inner).enumerate().with_min_len((4096 / inner).max(1)).for_each(row);
    } else {
        out.chunks_mut(inner).enumerate().for_each(row);
    }
}

/// Row `i` of [`axis_pass`] within one block of rows (`inner` values each),
/// its inputs summed in increasing order.
struct AxisRow<'a> {
    taps: &'a [f64],
    block: &'a [f64],
    inner: usize,
    i: usize,
    o: &'a mut [f64],
}

impl pulp::WithSimd for AxisRow<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let AxisRow { taps, block, inner, i, o } = self;
        let (len, reach) = (block.len() / inner, taps.len() - 1);
        let (from, to) = (i.saturating_sub(reach), (i + reach + 1).min(len));
        for i2 in from..to {
            let g = taps[i.abs_diff(i2)];
            let src = &block[i2 * inner..(i2 + 1) * inner];
            for (ov, sv) in o.iter_mut().zip(src) {
                *ov += g * sv;
            }
        }
    }
}

/// Targets per dispatched chunk of the gather.
const GATHER_CHUNK: usize = 64;

/// One chunk of targets' rows: the targets from `first`, values `..split`
/// of each row into `o1`, the rest into `o2`.
struct Gather<'a, const D: usize, const P: usize, const MODE: u8> {
    fields: &'a Fields<'a>,
    inp: &'a Inputs<'a>,
    h: f64,
    basis: &'a Basis,
    first: usize,
    rows: usize,
    split: usize,
    o1: &'a mut [f64],
    o2: &'a mut [f64],
}

impl<const D: usize, const P: usize, const MODE: u8> pulp::WithSimd for Gather<'_, D, P, MODE> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let (split, w2) = (self.split, self.rows - self.split);
        let n = self.o1.len() / split.max(1);
        for t in 0..n {
            let mut row = [0.0; MAX_CHANNELS + 3];
            gather::<D, P, MODE>(self.fields, self.inp, self.first + t, (self.h, self.basis), &mut row[..self.rows]);
            self.o1[t * split..(t + 1) * split].copy_from_slice(&row[..split]);
            self.o2[t * w2..(t + 1) * w2].copy_from_slice(&row[split..self.rows]);
        }
    }
}

/// The convolved fields a gather reads (channel-major).
struct Fields<'a> {
    phi: &'a [f64],
    dphi: &'a [f64],
    win: Window,
    c: usize,
}

/// Contractions of one channel of a field with one target's stencil: the
/// value V, the gradient G (with `GRAD`), and the Hessian H (xx, xy, xz,
/// yy, yz, zz; with `HESS`).
#[derive(Default, Clone, Copy)]
struct Contraction {
    v: f64,
    g: [f64; 3],
    h: [f64; 6],
}

/// Contracts channel `ch` of `field` with the stencil `st`: the rows
/// along axis 0 are summed over axes 1 and 2 first, P lanes wide (each
/// lane its own sum, so the compiler vectorises without reordering), then
/// contracted along axis 0.
#[inline(always)]
fn contract<const D: usize, const P: usize, const GRAD: bool, const HESS: bool>(
    field: &[f64],
    ch: usize,
    st: &[Axis<P>; 3],
    win: &Window,
) -> Contraction {
    let (nx, ny) = (win.n[0], win.n[1]);
    let pz = if D == 3 { P } else { 1 };
    let x0 = (st[0].first - win.lo[0]) as usize;
    let (gy0, gz0) = ((st[1].first - win.lo[1]) as usize, (st[2].first - win.lo[2]) as usize);
    let channel = &field[ch * win.nodes()..(ch + 1) * win.nodes()];
    // a[0] = Σ_z w_z Σ_y w_y φ; with GRAD a[1] (w_y'), a[2] (w_z'); with
    // HESS a[3] (w_y''), a[4] (w_z' w_y'), a[5] (w_z''): one lane per x.
    let mut a = [[0.0f64; P]; 6];
    for kz in 0..pz {
        let mut b = [[0.0f64; P]; 3];
        for ky in 0..P {
            let row = ((gz0 + kz) * ny + gy0 + ky) * nx + x0;
            let vals: &[f64; P] = channel[row..row + P].try_into().expect("P values");
            let (wy, dwy, ddwy) = (st[1].w[ky], st[1].dw[ky], st[1].ddw[ky]);
            for kx in 0..P {
                b[0][kx] += wy * vals[kx];
                if GRAD {
                    b[1][kx] += dwy * vals[kx];
                }
                if HESS {
                    b[2][kx] += ddwy * vals[kx];
                }
            }
        }
        let (wz, dwz, ddwz) = (st[2].w[kz], st[2].dw[kz], st[2].ddw[kz]);
        for kx in 0..P {
            a[0][kx] += wz * b[0][kx];
            if GRAD {
                a[1][kx] += wz * b[1][kx];
                a[2][kx] += dwz * b[0][kx];
            }
            if HESS {
                a[3][kx] += wz * b[2][kx];
                a[4][kx] += dwz * b[1][kx];
                a[5][kx] += ddwz * b[0][kx];
            }
        }
    }
    let along = |w: &[f64; P], lanes: &[f64; P]| {
        let mut s = 0.0;
        for kx in 0..P {
            s += w[kx] * lanes[kx];
        }
        s
    };
    let (w, dw, ddw) = (&st[0].w, &st[0].dw, &st[0].ddw);
    let mut out = Contraction { v: along(w, &a[0]), ..Contraction::default() };
    if GRAD {
        out.g = [along(dw, &a[0]), along(w, &a[1]), along(w, &a[2])];
    }
    if HESS {
        // xx, xy, xz, yy, yz, zz.
        out.h =
            [along(ddw, &a[0]), along(dw, &a[1]), along(dw, &a[2]), along(w, &a[3]), along(w, &a[4]), along(w, &a[5])];
    }
    out
}

/// One target's output row for `MODE` (layouts of `fast.rs`: CONV c
/// values, GRAD D, CONV_GRAD c then D, CONV_JVP c, GRAD_JVP D, BOTH_JVP
/// c then D).
#[inline(always)]
fn gather<const D: usize, const P: usize, const MODE: u8>(
    f: &Fields<'_>,
    inp: &Inputs<'_>,
    i: usize,
    (h, basis): (f64, &Basis),
    row: &mut [f64],
) {
    let c = f.c;
    let st = stencil::<D, P>(&inp.x[i * D..(i + 1) * D], h, basis);
    let conv = MODE == CONV || MODE == CONV_GRAD;
    let jvp = MODE == CONV_JVP || MODE == GRAD_JVP || MODE == BOTH_JVP;
    let mut k = [Contraction::default(); MAX_CHANNELS];
    if !jvp {
        let at = if conv { c } else { 0 };
        if MODE == CONV {
            for ch in 0..c {
                row[ch] = contract::<D, P, false, false>(f.phi, ch, &st, &f.win).v;
            }
            return;
        }
        for ch in 0..c {
            k[ch] = contract::<D, P, true, false>(f.phi, ch, &st, &f.win);
            if conv {
                row[ch] = k[ch].v;
            }
        }
        let ai = &inp.a[i * c..(i + 1) * c];
        for axis in 0..D {
            row[at + axis] = (0..c).map(|ch| ai[ch] * k[ch].g[axis]).sum();
        }
        return;
    }
    let want_grad = MODE == GRAD_JVP || MODE == BOTH_JVP;
    let mut dk = [Contraction::default(); MAX_CHANNELS];
    for ch in 0..c {
        if want_grad {
            k[ch] = contract::<D, P, true, true>(f.phi, ch, &st, &f.win);
            dk[ch] = contract::<D, P, true, false>(f.dphi, ch, &st, &f.win);
        } else {
            k[ch] = contract::<D, P, true, false>(f.phi, ch, &st, &f.win);
            dk[ch] = contract::<D, P, false, false>(f.dphi, ch, &st, &f.win);
        }
    }
    let dxi = &inp.dx[i * D..(i + 1) * D];
    let mut at = 0;
    if MODE == CONV_JVP || MODE == BOTH_JVP {
        for ch in 0..c {
            row[ch] = dk[ch].v + (0..D).map(|a| k[ch].g[a] * dxi[a]).sum::<f64>();
        }
        at = c;
    }
    if want_grad {
        let (ai, dai) = (&inp.a[i * c..(i + 1) * c], &inp.da[i * c..(i + 1) * c]);
        // Hessian index of (a, b).
        const HI: [[usize; 3]; 3] = [[0, 1, 2], [1, 3, 4], [2, 4, 5]];
        for axis in 0..D {
            let mut v = 0.0;
            for ch in 0..c {
                let hdx: f64 = (0..D).map(|b| k[ch].h[HI[axis][b]] * dxi[b]).sum();
                v += ai[ch] * hdx + dai[ch] * k[ch].g[axis] + ai[ch] * dk[ch].g[axis];
            }
            row[at + axis] = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cardinal B-spline N_p by its explicit formula
    /// N_p(u) = 1/(p−1)! Σ_k (−1)^k C(p, k) (u − k)_+^{p−1}.
    fn cardinal(p: usize, u: f64) -> f64 {
        let mut fact = 1.0;
        for q in 1..p {
            fact *= q as f64;
        }
        let mut binom = 1.0;
        let mut s = 0.0;
        for k in 0..=p {
            let t = u - k as f64;
            if t > 0.0 {
                s += if k % 2 == 0 { 1.0 } else { -1.0 } * binom * t.powi(p as i32 - 1);
            }
            binom = binom * (p - k) as f64 / (k + 1) as f64;
        }
        s / fact
    }

    /// The stencil of order `p` (a runtime value) as vectors.
    fn axis(x: f64, h: f64, p: usize) -> Axis<8> {
        fn widen<const P: usize>(a: Axis<P>) -> Axis<8> {
            let mut out = Axis { first: a.first, w: [0.0; 8], dw: [0.0; 8], ddw: [0.0; 8] };
            out.w[..P].copy_from_slice(&a.w);
            out.dw[..P].copy_from_slice(&a.dw);
            out.ddw[..P].copy_from_slice(&a.ddw);
            out
        }
        let basis = Basis::new(p, h);
        match p {
            4 => widen(Axis::<4>::of(x, h, &basis)),
            6 => widen(Axis::<6>::of(x, h, &basis)),
            _ => Axis::<8>::of(x, h, &basis),
        }
    }

    #[test]
    fn stencils_are_the_centred_b_spline_and_its_derivatives() {
        let h = 0.7;
        for p in GRID_ORDERS {
            for &x in &[-3.21, -0.35, 0.0, 0.35, 1.4, 2.9999, 5.123] {
                let st = axis(x, h, p);
                for k in 0..p {
                    let node = (st.first + k as i64) as f64 * h;
                    // W(x − g) = M_p((x − g)/h) = N_p((x − g)/h + p/2).
                    let m = |x: f64| cardinal(p, (x - node) / h + 0.5 * p as f64);
                    // The explicit formula cancels to ~1e-12 at order 8.
                    assert!((st.w[k] - m(x)).abs() < 1e-11, "p {p} x {x} k {k}");
                    let e = 1e-4;
                    let d = (m(x + e) - m(x - e)) / (2.0 * e);
                    assert!((st.dw[k] - d).abs() < 1e-6, "p {p} x {x} k {k}: {} vs {d}", st.dw[k]);
                    // A wider step, away from the knots, where N_p'' has a kink.
                    let e = 1e-3;
                    let v = x / h - 0.5 * p as f64;
                    if (v - v.round()).abs() < 0.01 {
                        continue;
                    }
                    let dd = (m(x + e) - 2.0 * m(x) + m(x - e)) / (e * e);
                    assert!(
                        (st.ddw[k] - dd).abs() < 1e-4 * (1.0 + dd.abs()),
                        "p {p} x {x} k {k}: {} vs {dd}",
                        st.ddw[k]
                    );
                }
                let sum: f64 = st.w[..p].iter().sum();
                // Partition of unity; the nodes outside carry nothing.
                assert!((sum - 1.0).abs() < 1e-14);
                for k in [-1i64, p as i64] {
                    let node = (st.first + k) as f64 * h;
                    assert!(cardinal(p, (x - node) / h + 0.5 * p as f64).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn filters_sum_to_the_gaussian_spectrum_at_zero() {
        // Σ_l G_l = Γ(0) = h k̂(0)/Ŵ(0)² = σ√(2π)/h.
        for p in GRID_ORDERS {
            for s in [2.5, 4.0, 6.0] {
                let (g, _) = filter(s, p);
                let total = g[0] + 2.0 * g[1..].iter().sum::<f64>();
                let expected = s * (2.0 * std::f64::consts::PI).sqrt();
                assert!((total - expected).abs() < 1e-9 * expected, "p {p} s {s}: {total} vs {expected}");
            }
        }
    }

    #[test]
    fn the_bound_falls_with_the_spacing_and_the_order() {
        let t4 = AliasTables::new(4);
        let t6 = AliasTables::new(6);
        let (a, b) = (t4.bound(2.0).0, t4.bound(3.0).0);
        assert!(b < a / 4.0, "{a} {b}");
        assert!(t6.bound(3.0).0 < b, "{} {b}", t6.bound(3.0).0);
        // The spacing found for a tolerance meets it, a little wider does not.
        for (p, tol) in [(4, 1e-4), (6, 1e-4), (6, 1e-6), (8, 1e-6), (8, 1e-9)] {
            let t = AliasTables::new(p);
            let meets = |s: f64| {
                let (v, g) = t.worst(s, filter(s, p).1, 3);
                v <= tol && g <= GRADIENT_SLACK * tol
            };
            let s = ratio_for(tol, p, 3);
            assert!(meets(s) && !meets(s / 1.05), "p {p} tol {tol}: s {s}");
        }
    }

    #[test]
    fn every_instruction_set_gives_the_same_bits() {
        use crate::fast::{BOTH_JVP, CONV_GRAD};
        let k = crate::Kernel::try_new(&crate::Profile::Gaussians { sigmas: vec![0.3, 0.15], weights: vec![1.0, 0.5] })
            .unwrap();
        let mut seed = 3u64;
        let mut rnd = move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for (dim, order) in [(2, 4), (3, 6), (3, 8)] {
            let grid = k.on_grid(k.grid_spacing(1e-6, order, dim).unwrap(), order, dim).unwrap();
            let terms = grid.gaussian_terms_untruncated().unwrap();
            let n = 300;
            let [x, dx, b, db]: [Vec<f64>; 4] =
                std::array::from_fn(|i| (0..n * if i < 2 { dim } else { 3 }).map(|_| rnd()).collect());
            let inp = Inputs { x: &x, dx: &dx, y: &x, dy: &dx, a: &b, da: &db, b: &b, db: &db };
            let run = |scalar: bool| {
                let mut ws = GridWorkspace { scalar, ..GridWorkspace::default() };
                let (mut c1, mut g1) = (vec![0.0; n * 3], vec![0.0; n * dim]);
                let (mut c2, mut g2) = (vec![0.0; n * 3], vec![0.0; n * dim]);
                let g = grid.grid().unwrap();
                grid_sum_into::<CONV_GRAD>(g, &terms, inp, dim, 3, true, &mut ws, 3, &mut c1, &mut g1).unwrap();
                grid_sum_into::<BOTH_JVP>(g, &terms, inp, dim, 3, true, &mut ws, 3, &mut c2, &mut g2).unwrap();
                [c1, g1, c2, g2]
            };
            assert!(run(true) == run(false), "dim {dim} order {order}");
        }
    }

    #[test]
    fn erfc_matches_known_values() {
        for (x, v) in [
            (0.0, 1.0),
            (0.5, 0.479_500_122_186_953_5),
            (2.0, 0.004_677_734_981_047_266),
            (4.0, 1.541_725_790_028_002e-8),
        ] {
            let e: f64 = erfc(x);
            assert!(e >= v && (e - v) <= 2e-7 * v, "{x}: {e} vs {v}");
        }
    }
}
