//! Principal component analysis of an atlas's initial momenta (tangent
//! PCA): the population's Gram matrix diagonalised by faer
//! ([`crate::linalg::symmetric_eigen`]).

use fshape_fem::SignalNorm;
use fshape_mesh::FShape;
use fshape_shoot::{ModelKind, Problem, ShootError};

use super::{AtlasResult, Population};
use crate::{MatchError, Runner};

/// One principal mode of the population's initial momenta.
#[derive(Clone, Debug)]
pub struct Mode {
    /// Its standard deviation over the population (in the metric's units:
    /// √(2 × energy)).
    pub sd: f64,
    /// Its share of the total variance.
    pub share: f64,
    /// The unit direction (p_0, p^f or ζ) on the template's vertices.
    pub p0: Vec<f64>,
    /// Its signal part.
    pub pf: Vec<f64>,
}

/// Principal component analysis of an atlas's initial momenta.
#[derive(Clone, Debug)]
pub struct Modes {
    /// The subjects' mean momenta.
    pub mean_p0: Vec<f64>,
    /// Their mean signal momentum.
    pub mean_pf: Vec<f64>,
    /// The modes, largest variance first.
    pub modes: Vec<Mode>,
    /// Per subject, its coordinate along each mode.
    pub scores: Vec<Vec<f64>>,
}

impl Runner<Population> {
    /// The principal modes of the subjects' initial momenta (at most
    /// `count`), in the metric of the geodesic energy at the template:
    /// ⟨m, m'⟩ = ⟨p_0, K p_0'⟩/γ_V + ⟨p^f, D_s⁻¹ p^f'⟩/γ_f (metamorphosis;
    /// LDDMM without the second term; tangential with γ_f⟨ζ, D_s ζ'⟩), so
    /// that a mode's variance is an energy, independent of the mesh (the
    /// momenta are densities). The Gram matrix of the centred momenta is
    /// diagonalised (Deformetrica's and Vaillant et al.'s tangent PCA); a
    /// mode is the combination of the subjects' momenta along its
    /// eigenvector, of unit norm.
    pub fn principal_modes(&self, result: &AtlasResult, count: usize) -> Result<Modes, MatchError> {
        let subjects = &result.subjects;
        let n = subjects.len();
        let t = &result.template;
        let (pn, k) = (t.n_vertices() * t.dim(), t.n_channels().max(1));
        // p^f's length: P·k (0 for LDDMM).
        let p = subjects.first().map_or(0, |s| s.pf.len());
        let plan = self.plan();
        let kind = plan.model.kind();
        // Each subject's momenta paired with the metric: (K p_0/γ_V, the signal's).
        let tangential = if kind == ModelKind::Tangential {
            let fem = SignalNorm::try_new(&result.template, plan.model.norm()).map_err(ShootError::from)?;
            // Map c's weight γ_f·w_c, D_s applied to each map.
            let weights = plan.model.channel_weights();
            let g: Vec<f64> = (0..k).map(|c| plan.model.gamma_f() * weights.get(c).copied().unwrap_or(1.0)).collect();
            let paired = |pf: &[f64]| -> Result<Vec<f64>, ShootError> {
                let mut out = vec![0.0; pf.len()];
                for (c, gc) in g.iter().enumerate() {
                    let zeta: Vec<f64> = pf.iter().skip(c).step_by(k).copied().collect();
                    let d = fem.matvec(t.points(), &zeta)?;
                    for (o, v) in out.iter_mut().skip(c).step_by(k).zip(d) {
                        *o = gc * v;
                    }
                }
                Ok(out)
            };
            Some(subjects.iter().map(|s| paired(&s.pf)).collect::<Result<Vec<Vec<f64>>, ShootError>>()?)
        } else {
            None
        };
        let paired = |i: usize| -> (&[f64], &[f64]) {
            let (vx, vf) = subjects[i].trajectory.velocity(0);
            match &tangential {
                Some(t) => (vx, &t[i]),
                None => (vx, vf),
            }
        };
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let mut gram = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                let (vx, vf) = paired(j);
                gram[i * n + j] = dot(&subjects[i].p0, vx) + dot(&subjects[i].pf, vf);
            }
        }
        // Symmetric up to rounding; centred: C G C with C = I − 11ᵀ/n.
        let sym: Vec<f64> = (0..n * n).map(|k| 0.5 * (gram[k] + gram[(k % n) * n + k / n])).collect();
        let row_mean: Vec<f64> = (0..n).map(|i| sym[i * n..(i + 1) * n].iter().sum::<f64>() / n as f64).collect();
        let all_mean = row_mean.iter().sum::<f64>() / n as f64;
        let centred: Vec<f64> = (0..n * n).map(|k| sym[k] - row_mean[k / n] - row_mean[k % n] + all_mean).collect();
        let (values, vectors) = crate::linalg::symmetric_eigen(&centred, n)?;
        let total: f64 = values.iter().filter(|v| **v > 0.0).sum();
        let mean_p0: Vec<f64> = (0..pn).map(|k| subjects.iter().map(|s| s.p0[k]).sum::<f64>() / n as f64).collect();
        let mean_pf: Vec<f64> = (0..p).map(|k| subjects.iter().map(|s| s.pf[k]).sum::<f64>() / n as f64).collect();
        let mut modes = Vec::new();
        let dof = n.saturating_sub(1).max(1) as f64;
        for (k, &lambda) in values.iter().enumerate().take(count.min(n.saturating_sub(1))) {
            if lambda.is_nan() || lambda <= 1e-12 * total {
                break;
            }
            let root = lambda.sqrt();
            let weight = |i: usize| vectors[i * n + k] / root;
            let p0 = (0..pn).map(|c| (0..n).map(|i| weight(i) * (subjects[i].p0[c] - mean_p0[c])).sum()).collect();
            let pf = (0..p).map(|c| (0..n).map(|i| weight(i) * (subjects[i].pf[c] - mean_pf[c])).sum()).collect();
            modes.push(Mode { sd: (lambda / dof).sqrt(), share: lambda / total, p0, pf });
        }
        let scores =
            (0..n).map(|i| (0..modes.len()).map(|k| values[k].sqrt() * vectors[i * n + k]).collect()).collect();
        Ok(Modes { mean_p0, mean_pf, modes, scores })
    }

    /// The template of `result` shot by momenta (p_0, p^f): the shape at
    /// t = 1 (to see a mode at ±2 standard deviations).
    pub fn shoot_template(&mut self, result: &AtlasResult, p0: &[f64], pf: &[f64]) -> Result<FShape, MatchError> {
        let population = &mut self.staged;
        let model = population.stages.plan.model.clone();
        let level = population.ensure_level(population.stages.plan.stages.len() - 1)?;
        let t = &result.template;
        let mut spare;
        let problem = match level.problems.first_mut() {
            Some(p) => p,
            None => {
                spare = Problem::new(&level.template, model)?;
                &mut spare
            }
        };
        problem.set_template(t.points(), t.signal())?;
        let traj = problem.shoot(p0, pf)?;
        let (last, k) = (traj.steps(), t.n_channels());
        Ok(t.clone().with_points(traj.points(last).to_vec())?.with_signals(Some(traj.signal(last).to_vec()), k)?)
    }
}
