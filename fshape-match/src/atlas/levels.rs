//! One resolution of an atlas: the initial template at it, the subjects'
//! problems, the packing of the unknowns; a stage's solution read off its
//! unknowns and carried to a finer level.

use fshape_mesh::FShape;
use fshape_shoot::{ModelKind, Problem};

use super::Cluster;
use super::Population;
use super::objective::{AtlasObjective, Hyper, TemplateMetric, positions};
use crate::unknowns::Unknowns;
use crate::{MatchError, Plan};

/// One resolution's working set: the initial template at it (with a
/// signal), the subjects' problems on it, the packing of their momenta,
/// the template blocks' metric and the hypertemplate's shooting.
pub(super) struct Level {
    pub(super) template: FShape,
    /// The problems of this process's subjects (`mine`), in order: the
    /// others are set up by the processes that evaluate them.
    pub(super) problems: Vec<Problem>,
    pub(super) mine: std::ops::Range<usize>,
    pub(super) unknowns: Unknowns,
    metric: TemplateMetric,
    hyper: Option<Hyper>,
    /// How the deformation kernel's sums are evaluated on this template.
    pub(super) deformation: String,
}

impl Level {
    pub(super) fn new(
        template: &FShape,
        mine: std::ops::Range<usize>,
        plan: &Plan,
        hyper: Option<&fshape_shoot::Model>,
    ) -> Result<Level, MatchError> {
        // Parallel over the subjects, each subject's work serial (the same
        // bits as parallel problems): the subjects fill the threads without
        // nested parallelism.
        let problems = mine
            .clone()
            .map(|_| Problem::new(template, plan.model.clone()).map(|p| p.with_parallel(false)))
            .collect::<Result<Vec<_>, _>>()?;
        let spare;
        let first = match problems.first() {
            Some(p) => p,
            None => {
                spare = Problem::new(template, plan.model.clone())?;
                &spare
            }
        };
        let deformation = first.model().kernel().path().to_string();
        let unknowns = Unknowns::scaled(first, plan.metrics, plan.scales.as_ref())?;
        let metric = TemplateMetric::new(template, plan.model.kernel(), plan.scales.as_ref())?;
        let hyper = match hyper {
            None => None,
            Some(model) => {
                let problem = Problem::new(template, model.clone())?;
                let unknowns = Unknowns::scaled(&problem, plan.metrics, plan.scales.as_ref())?;
                Some(Hyper { problem, unknowns })
            }
        };
        Ok(Level { template: template.clone(), problems, mine, unknowns, metric, hyper, deformation })
    }

    /// The template's positions and signal at the unknowns `x` of this
    /// level, and the hypertemplate's momenta and energy (0 without one).
    pub(super) fn template_at(&self, x: &[f64]) -> Result<(FShape, Option<Vec<f64>>, f64), MatchError> {
        let t = &self.template;
        let (pn, k) = (t.n_vertices() * t.dim(), t.n_channels());
        let p = t.n_vertices() * k;
        let (points, traj) = positions(self.hyper.as_ref(), &self.metric, &x[..pn])?;
        let signal = x[pn..pn + p].iter().zip(self.metric.signal.iter().cycle()).map(|(u, s)| u * s).collect();
        let momenta = self.hyper.as_ref().map(|h| h.unknowns.unpack(&x[..pn]).0);
        let energy = traj.map_or(0.0, |t| t.hamiltonian[0]);
        Ok((t.clone().with_points(points)?.with_signals(Some(signal), k)?, momenta, energy))
    }

    /// The unknowns at the start: the initial template (P_0 = 0 for the
    /// hypertemplate) and zero momenta.
    pub(super) fn start(&self, subjects: usize) -> Vec<f64> {
        let mut x: Vec<f64> = match self.hyper {
            // P_0 = 0: the template starts as the hypertemplate.
            Some(_) => vec![0.0; self.template.points().len()],
            None => self.template.points().iter().map(|v| v / self.metric.length).collect(),
        };
        let signal = known(self.template.signal().expect("levels carry a signal"));
        x.extend(signal.zip(self.metric.signal.iter().cycle()).map(|(v, s)| v / s));
        x.resize(x.len() + subjects * self.unknowns.len(), 0.0);
        x
    }

    pub(super) fn objective<'a>(&'a mut self, cluster: &'a dyn Cluster, n_subjects: usize) -> AtlasObjective<'a> {
        let t = &self.template;
        AtlasObjective {
            cluster,
            pn: t.n_vertices() * t.dim(),
            p: t.n_vertices() * t.n_channels(),
            problems: &mut self.problems,
            mine: self.mine.clone(),
            n_subjects,
            unknowns: self.unknowns.clone(),
            metric: &self.metric,
            hyper: self.hyper.as_ref(),
            evaluations: 0,
        }
    }
}

/// What a stage's solution says, independently of its mesh: the template
/// (its displacement and signal change from the level's initial template)
/// and every subject's momenta, with the hypertemplate's momenta.
pub(super) struct Solution {
    initial: FShape,
    pub(super) template: FShape,
    hyper_p0: Option<Vec<f64>>,
    pub(super) momenta: Vec<(Vec<f64>, Vec<f64>)>,
}

impl Population {
    /// Makes stage k's template the working level (this process's
    /// subjects only) and returns it.
    pub(super) fn ensure_level(&mut self, k: usize) -> Result<&mut Level, MatchError> {
        let key = self.stages.template_of(k).0;
        if self.level.is_none() || key != self.on {
            let mine = self.cluster.subjects(self.cluster.rank(), self.subjects.len());
            // The old level goes first: two levels' problems are not held at once.
            self.level = None;
            let template = self.stages.template_of(k).1;
            let level = Level::new(template, mine, &self.stages.plan, self.hyper_model.as_ref())?;
            self.level = Some(level);
            self.on = key;
            self.staged = None;
        }
        Ok(self.level.as_mut().expect("just built"))
    }

    /// The working level, after [`Atlas::ensure_level`].
    pub(super) fn level(&mut self) -> &mut Level {
        self.level.as_mut().expect("ensure_level runs first")
    }

    /// Stage k's unknowns `x` read as a [`Solution`].
    pub(super) fn solution(&mut self, k: usize, x: &[f64]) -> Result<Solution, MatchError> {
        let level = &*self.ensure_level(k)?;
        let (template, hyper_p0, _) = level.template_at(x)?;
        let t = &level.template;
        let offset = t.n_vertices() * (t.dim() + t.n_channels());
        let momenta = x[offset..].chunks_exact(level.unknowns.len()).map(|xi| level.unknowns.unpack(xi)).collect();
        Ok(Solution { initial: level.template.clone(), template, hyper_p0, momenta })
    }

    /// A solution carried to stage k's (finer) template, as its unknowns.
    fn prolongate(&mut self, k: usize, coarse: &Solution) -> Result<Vec<f64>, MatchError> {
        use crate::resolution::{VelocityFit, prolongate_fitted, sample};
        self.ensure_level(k)?;
        let level = self.level.as_ref().expect("ensured");
        let fine0 = &level.template;
        let (n, dim, k) = (fine0.n_vertices(), fine0.dim(), fine0.n_channels());
        let kind = self.stages.plan.model.kind();
        // The template's displacement and signal change, one pass of
        // closest points: dim + k values a vertex.
        let (now, was) = (&coarse.template, &coarse.initial);
        let signal_change: Vec<f64> =
            known(now.signal().expect("set")).zip(known(was.signal().expect("set"))).map(|(f, g)| f - g).collect();
        let change: Vec<f64> = now
            .points()
            .chunks_exact(dim)
            .zip(was.points().chunks_exact(dim))
            .zip(signal_change.chunks_exact(k))
            .flat_map(|((a, b), df)| a.iter().zip(b).map(|(a, b)| a - b).chain(df.iter().copied()))
            .collect();
        let change = sample(was, fine0, &change, dim + k)?;
        let signal: Vec<f64> = change
            .chunks_exact(dim + k)
            .flat_map(|d| d[dim..].iter().copied())
            .zip(known(fine0.signal().expect("levels carry a signal")))
            .map(|(d, f)| f + d)
            .collect();
        let (mut x, points) = match (&level.hyper, &coarse.hyper_p0) {
            (Some(h), Some(p0)) => {
                let zero = vec![0.0; was.n_vertices() * k];
                let (q0, _) = prolongate_fitted(was, fine0, p0, &zero, ModelKind::Lddmm, h.problem.model().kernel())?;
                let block = h.unknowns.pack(&q0, &[]);
                let (points, _) = positions(Some(h), &level.metric, &block)?;
                (block, points)
            }
            _ => {
                let points: Vec<f64> = fine0
                    .points()
                    .chunks_exact(dim)
                    .zip(change.chunks_exact(dim + k))
                    .flat_map(|(a, d)| a.iter().zip(d).map(|(a, d)| a + d))
                    .collect();
                (points.iter().map(|v| v / level.metric.length).collect(), points)
            }
        };
        x.extend(signal.iter().zip(level.metric.signal.iter().cycle()).map(|(v, s)| v / s));
        let fine = fine0.clone().with_points(points)?;
        // One factor on the (moved) fine template for every subject.
        let fit = VelocityFit::new(&fine, self.stages.plan.model.kernel())?;
        for (p0, pf) in &coarse.momenta {
            let (q0, qf) = fit.carry(&coarse.template, p0, pf, kind)?;
            x.extend(level.unknowns.pack(&q0, &qf));
        }
        debug_assert_eq!(x.len(), n * (dim + k) + self.subjects.len() * level.unknowns.len());
        Ok(x)
    }

    /// Stage `from`'s unknowns `x` carried to stage `to`'s template (as
    /// [`crate::Runner::run`] does between stages on different templates; `x`
    /// itself when the two stages share one).
    pub(super) fn prolongate_unknowns(&mut self, from: usize, x: &[f64], to: usize) -> Result<Vec<f64>, MatchError> {
        self.check_len(from, x)?;
        self.check_stage(to)?;
        if self.stages.template_of(from).0 == self.stages.template_of(to).0 {
            return Ok(x.to_vec());
        }
        let coarse = self.solution(from, x)?;
        self.prolongate(to, &coarse)
    }
}

/// A signal as unknowns: a masked vertex (NaN, no value) enters as 0. Its
/// gradient is 0 (the shooting projects it), so it stays 0, and the
/// template takes NaN there again when the unknowns become a shape.
fn known(signal: &[f64]) -> impl Iterator<Item = f64> + '_ {
    signal.iter().map(|&v| if v.is_nan() { 0.0 } else { v })
}
