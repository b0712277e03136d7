//! A general linear model per vertex, Y = X β + ε, and its contrast tested
//! by permutations (Freedman & Lane 1983, as FSL's randomise and PALM do,
//! Winkler et al. 2014).
//!
//! For a contrast C (r × p), the nuisance space is col(X N) with N a basis
//! of {b : C b = 0}: adding to the data anything in it changes neither
//! Cβ̂ nor the residuals. The data's part outside it, R_z = (I − H_z) Y, is
//! permuted across subjects and the statistic recomputed: with X = QR
//! (thin QR), W = Qᵀ P R_z, the effect Cβ̂ = L W with L = C R⁻¹, the
//! residual sum of squares ‖R_z‖² − ‖W‖² (a permutation keeps ‖R_z‖), and
//!
//! ```text
//! t = Cβ̂ / √(σ̂² L Lᵀ)                        (r = 1)
//! F = (Cβ̂)ᵀ (L Lᵀ)⁻¹ (Cβ̂) / (r σ̂²)          (r > 1),  σ̂² = RSS / (n − p)
//! ```
//!
//! Permutation 0 is the identity (the observed map). The family-wise
//! error over the vertices is controlled by the distribution of the map's
//! maximum over permutations: p_FWE(v) = #{k : max_k ≥ s(v)} / K. Each
//! permutation is drawn from its own generator (the seed and its index),
//! and the counts are integers, so the result has the same bits for any
//! number of threads.
//!
//! Multivariate tests (momenta scores, one row per subject) use the same
//! permutations on the Hotelling–Lawley trace, tr(H E⁻¹) × (n − p), with H
//! and E the hypothesis and error sums of squares and products: for two
//! groups this is Hotelling's two-sample T².

use rayon::prelude::*;

use crate::design::{Contrast, Design};
use crate::tfce::{MeshGraph, TfceParams, tfce, tfce_signed};
use crate::{StatsError, linalg};

/// Which values of a t statistic count as evidence.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Tail {
    /// Both signs: |t| (the default).
    #[default]
    TwoSided,
    /// Positive t only, as FSL's t contrasts (test −C for the other sign).
    Positive,
}

/// How a test is run.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Inference {
    /// Permutations, the identity included (p-values are multiples of
    /// 1/permutations).
    pub permutations: usize,
    /// The generator's seed.
    pub seed: u64,
    /// t tests' tail (F tests are one-sided by nature).
    pub tail: Tail,
    /// Threshold-free cluster enhancement, on top of the vertex-wise test.
    pub tfce: Option<TfceParams>,
}

impl Default for Inference {
    fn default() -> Inference {
        Inference { permutations: 5000, seed: 0, tail: Tail::TwoSided, tfce: None }
    }
}

/// Whether a statistic is Student's t or Fisher's F.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum StatKind {
    /// A one-row contrast.
    T,
    /// A contrast of several rows.
    F,
}

/// A map tested vertex by vertex.
#[derive(Clone, Debug, serde::Serialize)]
pub struct MapTest {
    /// t or F.
    pub kind: StatKind,
    /// Degrees of freedom: the contrast's rank and n − p.
    pub dof: (usize, usize),
    /// The statistic per vertex.
    pub statistic: Vec<f64>,
    /// t tests: the contrast's estimate Cβ̂ per vertex (in the map's unit,
    /// e.g. a group difference); F tests: its norm.
    pub effect: Vec<f64>,
    /// Uncorrected permutation p per vertex.
    pub p_uncorrected: Vec<f64>,
    /// Family-wise error corrected p per vertex (maximum statistic).
    pub p_fwe: Vec<f64>,
    /// TFCE of the statistic, and its corrected p, when asked for.
    pub tfce: Option<Vec<f64>>,
    /// FWE-corrected p of TFCE.
    pub tfce_p_fwe: Option<Vec<f64>>,
    /// The maxima over the map of every permutation, ascending (the
    /// observed one included): the null distribution the corrected p
    /// come from.
    pub max_null: Vec<f64>,
    /// Permutations run.
    pub permutations: usize,
}

impl MapTest {
    /// The value the statistic must reach for p_FWE ≤ alpha (on the
    /// scale of the tested value: |t| for two-sided tests).
    pub fn critical(&self, alpha: f64) -> f64 {
        let k = self.max_null.len();
        // The smallest m with #{max ≥ m}/k ≤ alpha.
        let allowed = (alpha * k as f64).floor() as usize;
        if allowed == 0 { f64::INFINITY } else { self.max_null[k - allowed] }
    }
}

/// A multivariate test on scores (one row per subject).
#[derive(Clone, Debug, serde::Serialize)]
pub struct ScoresTest {
    /// Hotelling–Lawley trace × (n − p): Hotelling's T² for one-row
    /// contrasts.
    pub statistic: f64,
    /// Permutation p.
    pub p: f64,
    /// Scores per subject.
    pub scores: usize,
    /// Permutations run.
    pub permutations: usize,
}

/// The fixed parts of one design and contrast.
struct Model {
    n: usize,
    p: usize,
    r: usize,
    /// X's orthonormal basis (n × p).
    q: Vec<f64>,
    /// L = C R⁻¹ (r × p).
    l: Vec<f64>,
    /// Cholesky factor of L Lᵀ (r × r).
    llt: Vec<f64>,
    /// Orthonormal basis of the nuisance space (n × pz).
    qz: Vec<f64>,
    pz: usize,
}

impl Model {
    fn new(design: &Design, contrast: &Contrast) -> Result<Model, StatsError> {
        let (n, p, r) = (design.n, design.p(), contrast.rank);
        if contrast.weights.len() != r * p {
            return Err(StatsError::Contrast {
                contrast: contrast.name.clone(),
                message: format!("{} weights for {r} rows of {p} design columns", contrast.weights.len()),
            });
        }
        let (q, rr) = linalg::qr(&design.x, n, p).map_err(|j| StatsError::Design {
            message: format!("column `{}` is a combination of the columns before it", design.columns[j]),
        })?;
        // L = C R⁻¹: solve Lᵀ from Rᵀ Lᵀ = Cᵀ, row by row of C (R upper).
        let mut l = vec![0.0; r * p];
        for a in 0..r {
            for j in 0..p {
                let s: f64 = contrast.weights[a * p + j] - (0..j).map(|k| l[a * p + k] * rr[k * p + j]).sum::<f64>();
                l[a * p + j] = s / rr[j * p + j];
            }
        }
        let mut llt = vec![0.0; r * r];
        for a in 0..r {
            for b in 0..r {
                llt[a * r + b] = (0..p).map(|j| l[a * p + j] * l[b * p + j]).sum();
            }
        }
        let llt = linalg::cholesky(&llt, r).ok_or_else(|| StatsError::Contrast {
            contrast: contrast.name.clone(),
            message: "its rows are linearly dependent".into(),
        })?;
        // Nuisance: X N, N ⟂ C's rows.
        let null = linalg::null_space(&contrast.weights, r, p);
        let pz = p - r;
        let mut z = vec![0.0; n * pz];
        for i in 0..n {
            for c in 0..pz {
                z[i * pz + c] = (0..p).map(|j| design.x[i * p + j] * null[j * pz + c]).sum();
            }
        }
        let qz = if pz == 0 {
            Vec::new()
        } else {
            linalg::qr(&z, n, pz)
                .map_err(|_| StatsError::Design {
                    message: "the nuisance part of the design is not of full rank".into(),
                })?
                .0
        };
        Ok(Model { n, p, r, q, l, llt, qz, pz })
    }

    fn dof(&self) -> usize {
        self.n - self.p
    }

    /// R_z = (I − Q_z Q_zᵀ) Y for Y n × m.
    fn residual_forming(&self, y: &[f64], m: usize) -> Vec<f64> {
        let mut rz = y.to_vec();
        for c in 0..self.pz {
            let mut proj = vec![0.0; m];
            for i in 0..self.n {
                let w = self.qz[i * self.pz + c];
                for (pv, yv) in proj.iter_mut().zip(&y[i * m..(i + 1) * m]) {
                    *pv += w * yv;
                }
            }
            for i in 0..self.n {
                let w = self.qz[i * self.pz + c];
                for (r, pv) in rz[i * m..(i + 1) * m].iter_mut().zip(&proj) {
                    *r -= w * pv;
                }
            }
        }
        rz
    }

    /// W = Qᵀ P R_z (p × m) for the permutation `perm` (row i of the
    /// permuted data is row perm[i] of R_z).
    fn project(&self, rz: &[f64], m: usize, perm: &[usize], w: &mut [f64]) {
        w.fill(0.0);
        for (i, &pi) in perm.iter().enumerate() {
            let row = &rz[pi * m..(pi + 1) * m];
            for j in 0..self.p {
                let qij = self.q[i * self.p + j];
                for (wv, rv) in w[j * m..(j + 1) * m].iter_mut().zip(row) {
                    *wv += qij * rv;
                }
            }
        }
    }

    /// The statistic and effect per column from W and ‖R_z‖² per column.
    fn statistic(&self, w: &[f64], norms: &[f64], stat: &mut [f64], effect: &mut [f64]) {
        let (m, p, r) = (norms.len(), self.p, self.r);
        let dof = self.dof() as f64;
        let (mut e, mut sol) = (vec![0.0; r], vec![0.0; r]);
        for v in 0..m {
            let fitted: f64 = (0..p).map(|j| w[j * m + v] * w[j * m + v]).sum();
            let rss = norms[v] - fitted;
            for (a, ea) in e.iter_mut().enumerate() {
                *ea = (0..p).map(|j| self.l[a * p + j] * w[j * m + v]).sum();
            }
            let sigma2 = rss / dof;
            if r == 1 {
                effect[v] = e[0];
                let se = (sigma2 * self.llt[0] * self.llt[0]).sqrt();
                stat[v] = if rss > 1e-13 * norms[v] && se > 0.0 { e[0] / se } else { 0.0 };
            } else {
                effect[v] = e.iter().map(|x| x * x).sum::<f64>().sqrt();
                sol.copy_from_slice(&e);
                linalg::cholesky_solve(&self.llt, r, &mut sol);
                let num: f64 = e.iter().zip(&sol).map(|(a, b)| a * b).sum::<f64>() / r as f64;
                stat[v] = if rss > 1e-13 * norms[v] && sigma2 > 0.0 { num / sigma2 } else { 0.0 };
            }
        }
    }
}

/// Permutation k of 0..n: the identity for k = 0, else a uniform shuffle
/// (Fisher–Yates) from a generator of its own.
fn permutation(seed: u64, k: usize, n: usize, out: &mut [usize]) {
    for (i, o) in out.iter_mut().enumerate() {
        *o = i;
    }
    if k == 0 {
        return;
    }
    let mut rng = fshape_mesh::generate::SplitMix64(seed ^ (k as u64).wrapping_mul(0xD1B5_4A32_D192_ED03));
    for i in (1..n).rev() {
        let j = ((u128::from(rng.next_u64()) * (i as u128 + 1)) >> 64) as usize;
        out.swap(i, j);
    }
}

fn check_values(values: &[f64], n: usize, m: usize, what: &str) -> Result<(), StatsError> {
    if values.len() != n * m {
        return Err(StatsError::Maps { message: format!("{what}: {} values for {n} subjects × {m}", values.len()) });
    }
    if let Some(k) = values.iter().position(|v| !v.is_finite()) {
        return Err(StatsError::Maps {
            message: format!("{what}: subject {}, entry {}: not a finite number", k / m, k % m),
        });
    }
    Ok(())
}

fn check_inference(inference: &Inference) -> Result<(), StatsError> {
    if inference.permutations == 0 {
        return Err(StatsError::Inference { message: "permutations must be at least 1 (the observed data)".into() });
    }
    if let Some(t) = inference.tfce
        && (!(t.extent > 0.0 && t.height > 0.0) || t.steps == 0)
    {
        return Err(StatsError::Inference {
            message: format!(
                "TFCE needs E > 0, H > 0 and steps > 0 (given E {}, H {}, steps {})",
                t.extent, t.height, t.steps
            ),
        });
    }
    Ok(())
}

/// What a permutation's maps give: the tested value per vertex.
fn tested(kind: StatKind, tail: Tail, v: f64) -> f64 {
    match (kind, tail) {
        (StatKind::T, Tail::TwoSided) => v.abs(),
        _ => v,
    }
}

/// Tests `contrast` at every vertex of `maps` (n subjects × `vertices`,
/// subject-major, in the design's row order). `graph` (the template's
/// mesh) is needed for TFCE.
pub fn test_maps(
    design: &Design,
    contrast: &Contrast,
    maps: &[f64],
    vertices: usize,
    graph: Option<&MeshGraph>,
    inference: &Inference,
) -> Result<MapTest, StatsError> {
    check_inference(inference)?;
    check_values(maps, design.n, vertices, "maps")?;
    if inference.tfce.is_some() && graph.is_none_or(|g| g.len() != vertices) {
        return Err(StatsError::Inference { message: format!("TFCE needs the mesh of the {vertices} vertices") });
    }
    let model = Model::new(design, contrast)?;
    let (n, m) = (model.n, vertices);
    let kind = if model.r == 1 { StatKind::T } else { StatKind::F };
    let rz = model.residual_forming(maps, m);
    let norms: Vec<f64> = (0..m).map(|v| (0..n).map(|i| rz[i * m + v] * rz[i * m + v]).sum()).collect();
    let enhance = |stat: &[f64], out: &mut [f64]| {
        if let (Some(params), Some(graph)) = (inference.tfce, graph) {
            match (kind, inference.tail) {
                (StatKind::T, Tail::TwoSided) => tfce_signed(stat, graph, params, out),
                _ => tfce(stat, graph, params, out),
            }
        }
    };
    // The observed maps.
    let perm: Vec<usize> = (0..n).collect();
    let mut w = vec![0.0; model.p * m];
    model.project(&rz, m, &perm, &mut w);
    let (mut statistic, mut effect) = (vec![0.0; m], vec![0.0; m]);
    model.statistic(&w, &norms, &mut statistic, &mut effect);
    let mut enhanced = vec![0.0; m];
    enhance(&statistic, &mut enhanced);
    let observed: Vec<f64> = statistic.iter().map(|&s| tested(kind, inference.tail, s)).collect();
    let observed_tfce: Vec<f64> = enhanced.iter().map(|&s| tested(kind, inference.tail, s)).collect();

    struct Acc {
        counts: Vec<u32>,
        maxima: Vec<(usize, f64, f64)>,
        perm: Vec<usize>,
        w: Vec<f64>,
        stat: Vec<f64>,
        effect: Vec<f64>,
        enhanced: Vec<f64>,
    }
    let fresh = || Acc {
        counts: vec![0; m],
        maxima: Vec::new(),
        perm: vec![0; n],
        w: vec![0.0; model.p * m],
        stat: vec![0.0; m],
        effect: vec![0.0; m],
        enhanced: vec![0.0; m],
    };
    let acc = (0..inference.permutations)
        .into_par_iter()
        .with_min_len(4)
        .fold(fresh, |mut acc, k| {
            permutation(inference.seed, k, n, &mut acc.perm);
            model.project(&rz, m, &acc.perm, &mut acc.w);
            model.statistic(&acc.w, &norms, &mut acc.stat, &mut acc.effect);
            let mut max = f64::NEG_INFINITY;
            for (v, &s) in acc.stat.iter().enumerate() {
                let x = tested(kind, inference.tail, s);
                max = max.max(x);
                acc.counts[v] += u32::from(x >= observed[v]);
            }
            let mut max_tfce = f64::NEG_INFINITY;
            if inference.tfce.is_some() {
                enhance(&acc.stat, &mut acc.enhanced);
                max_tfce =
                    acc.enhanced.iter().map(|&s| tested(kind, inference.tail, s)).fold(f64::NEG_INFINITY, f64::max);
            }
            acc.maxima.push((k, max, max_tfce));
            acc
        })
        .map(|a| (a.counts, a.maxima))
        .reduce(
            || (vec![0; m], Vec::new()),
            |(mut c1, mut m1), (c2, m2)| {
                for (a, b) in c1.iter_mut().zip(c2) {
                    *a += b;
                }
                m1.extend(m2);
                (c1, m1)
            },
        );
    let (counts, mut maxima) = acc;
    maxima.sort_by_key(|x| x.0);
    let total = inference.permutations as f64;
    let corrected = |sorted: &[f64], x: f64| (sorted.len() - sorted.partition_point(|&m| m < x)) as f64 / total;
    let mut max_null: Vec<f64> = maxima.iter().map(|x| x.1).collect();
    max_null.sort_by(f64::total_cmp);
    let p_fwe = observed.iter().map(|&x| corrected(&max_null, x)).collect();
    let (tfce_map, tfce_p_fwe) = if inference.tfce.is_some() {
        let mut null: Vec<f64> = maxima.iter().map(|x| x.2).collect();
        null.sort_by(f64::total_cmp);
        (Some(enhanced), Some(observed_tfce.iter().map(|&x| corrected(&null, x)).collect()))
    } else {
        (None, None)
    };
    Ok(MapTest {
        kind,
        dof: (model.r, model.dof()),
        statistic,
        effect,
        p_uncorrected: counts.iter().map(|&c| f64::from(c) / total).collect(),
        p_fwe,
        tfce: tfce_map,
        tfce_p_fwe,
        max_null,
        permutations: inference.permutations,
    })
}

/// [`test_maps`] on the vertices `tested` marks (a template's unmasked
/// vertices): the others are left out of everything — their values in
/// `maps` are not read (NaN is fine there), they do not enter the maximum
/// statistic, and TFCE's graph is the mesh without them
/// ([`MeshGraph::restricted`]), so no cluster crosses them. Every
/// per-vertex output is NaN there.
pub fn test_maps_within(
    design: &Design,
    contrast: &Contrast,
    maps: &[f64],
    tested: &[bool],
    graph: Option<&MeshGraph>,
    inference: &Inference,
) -> Result<MapTest, StatsError> {
    let m = tested.len();
    if maps.len() != design.n * m {
        return Err(StatsError::Maps {
            message: format!("maps: {} values for {} subjects × {m}", maps.len(), design.n),
        });
    }
    if graph.is_some_and(|g| g.len() != m) {
        return Err(StatsError::Inference { message: format!("TFCE needs the mesh of the {m} vertices") });
    }
    let kept: Vec<usize> = (0..m).filter(|&v| tested[v]).collect();
    if kept.is_empty() {
        return Err(StatsError::Maps { message: "every vertex is masked: nothing to test".into() });
    }
    let compact: Vec<f64> = maps.chunks_exact(m).flat_map(|row| kept.iter().map(|&v| row[v])).collect();
    let graph = graph.map(|g| g.restricted(tested));
    let test = test_maps(design, contrast, &compact, kept.len(), graph.as_ref(), inference)?;
    let expand = |values: Vec<f64>| {
        let mut full = vec![f64::NAN; m];
        for (&v, x) in kept.iter().zip(values) {
            full[v] = x;
        }
        full
    };
    Ok(MapTest {
        statistic: expand(test.statistic),
        effect: expand(test.effect),
        p_uncorrected: expand(test.p_uncorrected),
        p_fwe: expand(test.p_fwe),
        tfce: test.tfce.map(expand),
        tfce_p_fwe: test.tfce_p_fwe.map(expand),
        ..test
    })
}

/// Tests `contrast` on the subjects' `scores` (n × `k`, subject-major):
/// the Hotelling–Lawley trace with Freedman–Lane permutations.
pub fn test_scores(
    design: &Design,
    contrast: &Contrast,
    scores: &[f64],
    k: usize,
    inference: &Inference,
) -> Result<ScoresTest, StatsError> {
    check_inference(inference)?;
    check_values(scores, design.n, k, "scores")?;
    let model = Model::new(design, contrast)?;
    let (n, p, r) = (model.n, model.p, model.r);
    if k == 0 || n < p + k + 1 {
        return Err(StatsError::Inference {
            message: format!("{k} scores need at least {} subjects for {p} design columns (there are {n})", p + k + 1),
        });
    }
    let rz = model.residual_forming(scores, k);
    let mut gram = vec![0.0; k * k];
    for i in 0..n {
        for a in 0..k {
            for b in 0..k {
                gram[a * k + b] += rz[i * k + a] * rz[i * k + b];
            }
        }
    }
    let trace = |perm: &[usize]| -> Result<f64, StatsError> {
        let mut w = vec![0.0; p * k];
        model.project(&rz, k, perm, &mut w);
        // E = R_zᵀR_z − WᵀW; e = L W (r × k); H = eᵀ (LLᵀ)⁻¹ e.
        let mut e_mat = gram.clone();
        for a in 0..k {
            for b in 0..k {
                e_mat[a * k + b] -= (0..p).map(|j| w[j * k + a] * w[j * k + b]).sum::<f64>();
            }
        }
        let chol = linalg::cholesky(&e_mat, k).ok_or_else(|| StatsError::Inference {
            message:
                "the scores' residual covariance is singular (a score is a combination of the others or of the design)"
                    .into(),
        })?;
        let e: Vec<f64> =
            (0..r * k).map(|ak| (0..p).map(|j| model.l[(ak / k) * p + j] * w[j * k + ak % k]).sum()).collect();
        // (LLᵀ)⁻¹ e, column by column.
        let mut s = e.clone();
        for c in 0..k {
            let mut col: Vec<f64> = (0..r).map(|a| s[a * k + c]).collect();
            linalg::cholesky_solve(&model.llt, r, &mut col);
            for a in 0..r {
                s[a * k + c] = col[a];
            }
        }
        // tr(E⁻¹ H) with H = eᵀ s: Σ_c (E⁻¹ H)_{cc}.
        let mut tr = 0.0;
        for c in 0..k {
            let mut h_col: Vec<f64> = (0..k).map(|a| (0..r).map(|b| e[b * k + a] * s[b * k + c]).sum()).collect();
            linalg::cholesky_solve(&chol, k, &mut h_col);
            tr += h_col[c];
        }
        Ok(tr * model.dof() as f64)
    };
    let observed = trace(&(0..n).collect::<Vec<_>>())?;
    let exceed: usize = (0..inference.permutations)
        .into_par_iter()
        .map(|j| {
            let mut perm = vec![0; n];
            permutation(inference.seed, j, n, &mut perm);
            trace(&perm).map(|t| usize::from(t >= observed))
        })
        .collect::<Result<Vec<_>, _>>()?
        .into_iter()
        .sum();
    Ok(ScoresTest {
        statistic: observed,
        p: exceed as f64 / inference.permutations as f64,
        scores: k,
        permutations: inference.permutations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use fshape_mesh::generate::SplitMix64;

    /// Least squares by the normal equations, written out: β, residuals.
    fn ols(x: &[f64], n: usize, p: usize, y: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let mut xtx = vec![0.0; p * p];
        let mut xty = vec![0.0; p];
        for i in 0..n {
            for a in 0..p {
                xty[a] += x[i * p + a] * y[i];
                for b in 0..p {
                    xtx[a * p + b] += x[i * p + a] * x[i * p + b];
                }
            }
        }
        let l = linalg::cholesky(&xtx, p).unwrap();
        linalg::cholesky_solve(&l, p, &mut xty);
        let res = (0..n).map(|i| y[i] - (0..p).map(|a| x[i * p + a] * xty[a]).sum::<f64>()).collect();
        (xty, res)
    }

    /// The obvious Freedman–Lane t at one vertex: fit the nuisance Z,
    /// permute its residuals, add its fit back, fit X, t from the
    /// textbook formula c'β / √(σ² c'(X'X)⁻¹c).
    fn naive_t(design: &Design, c: &[f64], y: &[f64], perm: &[usize]) -> f64 {
        let (n, p) = (design.n, design.p());
        let null = linalg::null_space(c, 1, p);
        let pz = p - 1;
        let z: Vec<f64> =
            (0..n * pz).map(|ic| (0..p).map(|j| design.x[(ic / pz) * p + j] * null[j * pz + ic % pz]).sum()).collect();
        let (_, rz) = ols(&z, n, pz, y);
        let fit_z: Vec<f64> = y.iter().zip(&rz).map(|(a, b)| a - b).collect();
        let ystar: Vec<f64> = (0..n).map(|i| rz[perm[i]] + fit_z[i]).collect();
        let (beta, res) = ols(&design.x, n, p, &ystar);
        let sigma2 = res.iter().map(|r| r * r).sum::<f64>() / (n - p) as f64;
        // c'(X'X)⁻¹c.
        let mut xtx = vec![0.0; p * p];
        for i in 0..n {
            for a in 0..p {
                for b in 0..p {
                    xtx[a * p + b] += design.x[i * p + a] * design.x[i * p + b];
                }
            }
        }
        let l = linalg::cholesky(&xtx, p).unwrap();
        let mut sol = c.to_vec();
        linalg::cholesky_solve(&l, p, &mut sol);
        let var: f64 = c.iter().zip(&sol).map(|(a, b)| a * b).sum();
        let effect: f64 = c.iter().zip(&beta).map(|(a, b)| a * b).sum();
        effect / (sigma2 * var).sqrt()
    }

    #[test]
    #[expect(clippy::needless_range_loop, reason = "v indexes several maps at once")]
    fn statistics_and_p_values_match_the_textbook_freedman_lane_on_random_data() {
        let mut rng = SplitMix64(11);
        let (n, m) = (14, 30);
        let x: Vec<f64> = (0..n).flat_map(|i| [1.0, f64::from(u8::from(i % 2 == 0)), rng.range(20.0, 60.0)]).collect();
        let design = Design::from_matrix(vec!["intercept".into(), "group".into(), "age".into()], x).unwrap();
        // Data with a real age effect (the nuisance) and noise.
        let maps: Vec<f64> = (0..n * m).map(|k| 0.05 * design.x[(k / m) * 3 + 2] + rng.range(-1.0, 1.0)).collect();
        for (spec, c) in [("group", [0.0, 1.0, 0.0]), ("0,0,-1", [0.0, 0.0, -1.0])] {
            let contrast = design.contrast(spec).unwrap();
            let inference = Inference { permutations: 300, seed: 5, ..Inference::default() };
            let test = test_maps(&design, &contrast, &maps, m, None, &inference).unwrap();
            let column = |v: usize| -> Vec<f64> { (0..n).map(|i| maps[i * m + v]).collect() };
            let identity: Vec<usize> = (0..n).collect();
            let observed: Vec<f64> = (0..m).map(|v| naive_t(&design, &c, &column(v), &identity)).collect();
            for v in 0..m {
                assert!((test.statistic[v] - observed[v]).abs() < 1e-10 * observed[v].abs().max(1.0));
            }
            // Every permutation's map, the obvious way.
            let mut counts = vec![0usize; m];
            let mut maxima = Vec::new();
            let mut perm = vec![0; n];
            for k in 0..inference.permutations {
                permutation(inference.seed, k, n, &mut perm);
                let t: Vec<f64> = (0..m).map(|v| naive_t(&design, &c, &column(v), &perm).abs()).collect();
                for v in 0..m {
                    counts[v] += usize::from(t[v] >= observed[v].abs() - 1e-9);
                }
                maxima.push(t.iter().copied().fold(0.0, f64::max));
            }
            for v in 0..m {
                let p_unc = counts[v] as f64 / 300.0;
                let p_fwe = maxima.iter().filter(|&&mx| mx >= observed[v].abs() - 1e-9).count() as f64 / 300.0;
                assert!((test.p_uncorrected[v] - p_unc).abs() < 1.5 / 300.0, "{spec} vertex {v}");
                assert!((test.p_fwe[v] - p_fwe).abs() < 1.5 / 300.0, "{spec} vertex {v}");
                assert!(test.p_fwe[v] >= test.p_uncorrected[v]);
            }
        }
    }

    #[test]
    fn permutations_are_uniform_and_the_first_is_the_identity() {
        let n = 4;
        let mut seen = std::collections::HashMap::new();
        let mut perm = vec![0; n];
        permutation(3, 0, n, &mut perm);
        assert_eq!(perm, [0, 1, 2, 3]);
        let draws = 24_000;
        for k in 1..=draws {
            permutation(3, k, n, &mut perm);
            *seen.entry(perm.clone()).or_insert(0usize) += 1;
        }
        assert_eq!(seen.len(), 24);
        // Each of the 24 orderings ~1000 times (sd ≈ 31).
        assert!(seen.values().all(|&c| (850..1150).contains(&c)), "{seen:?}");
    }
}
