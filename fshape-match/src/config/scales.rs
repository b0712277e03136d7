//! The scales of the data that normalised weights are relative to: the
//! target's diagonal L, each map's deviation S_c and the cells' dimension
//! d (the module docs of `config` say how the weights use them).

use fshape_mesh::FShape;
use serde::{Deserialize, Serialize};

use super::check::bad;
use crate::MatchError;

/// The scales of the data that normalised weights are relative to
/// (module docs): L, S and d.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scales {
    /// L: the bounding-box diagonal.
    pub length: f64,
    /// S: the signal's standard deviation (1 without one); with several
    /// channels, the first channel's.
    pub signal: f64,
    /// d: the dimension of the cells (1 curves, 2 surfaces).
    pub cell_dim: usize,
    /// S_c, one per channel when there are several (empty with one).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub channels: Vec<f64>,
}

impl Scales {
    /// L from `target`, S (per channel) from the target's signal, else the
    /// template's, else 1; d from the template. A deviation is taken over
    /// the vertices that carry a value, weighted by their mask.
    pub fn of(template: &FShape, target: &FShape) -> Result<Scales, MatchError> {
        let length = target.bounding_box().diagonal();
        if !(length > 0.0 && length.is_finite()) {
            return Err(bad(
                "model.normalize",
                format!("the shapes' bounding-box diagonal is {length}; normalize = false"),
            ));
        }
        let k = target.n_channels().max(template.n_channels()).max(1);
        let deviation = |c: usize| deviation(target, c).or_else(|| deviation(template, c)).unwrap_or(1.0);
        let channels: Vec<f64> = if k > 1 { (0..k).map(deviation).collect() } else { Vec::new() };
        Ok(Scales { length, signal: deviation(0), cell_dim: template.kind().dim(), channels })
    }

    /// The effective (γ_V, γ_f, γ_W) of the written ones: γ_V/L²,
    /// γ_f/(S²·L^d), γ_W/L^{2d}.
    pub fn effective(&self, gamma_v: f64, gamma_f: f64, gamma_w: f64) -> (f64, f64, f64) {
        let (l, d) = (self.length, self.cell_dim as i32);
        (gamma_v / (l * l), gamma_f / (self.signal * self.signal * l.powi(d)), gamma_w / l.powi(2 * d))
    }

    /// The effective channel weights of the written ones `w` (empty: all
    /// 1): w_c·S²/S_c², so that channel c's γ_f is γ_f w_c/(S_c²·L^d) with
    /// [`Scales::effective`]'s γ_f. Empty with one channel.
    pub fn channel_weights(&self, w: &[f64]) -> Vec<f64> {
        let s2 = self.signal * self.signal;
        self.channels.iter().enumerate().map(|(c, sc)| w.get(c).copied().unwrap_or(1.0) * s2 / (sc * sc)).collect()
    }

    /// S_c of channel `c` (S with one channel).
    pub fn channel(&self, c: usize) -> f64 {
        self.channels.get(c).copied().unwrap_or(self.signal)
    }
}

/// The standard deviation of channel `c` of a shape's signal over the
/// vertices with a value, weighted by the mask; `None` without a signal,
/// or when it is constant there. Unmasked, it is the plain deviation
/// (weights of 1 change no bit).
fn deviation(s: &FShape, c: usize) -> Option<f64> {
    let k = s.n_channels();
    let f = s.signal().filter(|f| !f.is_empty() && c < k)?;
    let weight = |v: usize| s.mask().map_or(1.0, |m| m[v]);
    let values = || {
        f.iter()
            .skip(c)
            .step_by(k)
            .enumerate()
            .map(move |(v, &x)| (weight(v), x))
            .filter(|(w, x)| *w > 0.0 && !x.is_nan())
    };
    let total: f64 = values().map(|(w, _)| w).sum();
    let mean = values().map(|(w, x)| w * x).sum::<f64>() / total;
    let sd = (values().map(|(w, x)| w * (x - mean) * (x - mean)).sum::<f64>() / total).sqrt();
    (sd > 0.0 && sd.is_finite()).then_some(sd)
}
