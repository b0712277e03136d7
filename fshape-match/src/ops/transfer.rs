//! Values carried through a registration (`fshape transfer`): a map or
//! keys (a parcellation's or a label's) on one side's vertices read at the
//! other side's, by [`Correspondence`]'s rules, with the registration's
//! own mask and the caller's left out. The caller reads the registration
//! and the values, and writes what this returns.

use fshape_mesh::FShape;

use crate::MatchError;
use crate::transfer::{Carried, Correspondence};

/// What is carried, on the giving surface's vertices.
#[derive(Clone, Debug, PartialEq)]
pub enum TransferValues {
    /// A map: a number per vertex, NaN where it has none (interpolated).
    Map(Vec<f64>),
    /// Region keys, −1 for none (a parcellation's or a label's; never
    /// averaged).
    Keys(Vec<i32>),
}

/// A transfer: from the giving surface (the matched source, or the
/// target) onto the receiving one.
#[derive(Clone, Debug)]
pub struct TransferRequest<'a> {
    /// The surface the values are on.
    pub from: &'a FShape,
    /// The surface that receives them.
    pub onto: &'a FShape,
    /// The values, one per vertex of `from`.
    pub values: TransferValues,
    /// `from`'s vertices that give nothing (the caller's mask), beside
    /// those under 0.5 in `from`'s own mask when `run_mask`.
    pub masked: Vec<bool>,
    /// Whether `from`'s own mask (the registration's: its values did not
    /// count in the match) leaves its vertices out too.
    pub run_mask: bool,
    /// Receiving vertices farther than this from `from` get nothing.
    pub max_distance: f64,
    /// The length the distances are reported against (the target's
    /// bounding-box diagonal).
    pub diagonal: f64,
}

/// What a transfer gives.
#[derive(Clone, Debug)]
pub struct TransferRun {
    /// The values on `onto`'s vertices (NaN or −1 where none came).
    pub values: TransferValues,
    /// How many of `onto`'s vertices got nothing, and why.
    pub carried: Carried,
    /// `from`'s vertices left out (the caller's mask and, when applied,
    /// the registration's).
    pub masked: usize,
    /// Whether `from` had its own mask and it applied.
    pub run_mask: bool,
    /// The median, 95th percentile and largest distance of `onto`'s
    /// vertices to `from`, as percentages of `diagonal`.
    pub distance_percent: [f64; 3],
}

/// Carries `request.values` from `from` onto `onto` (module docs).
pub fn transfer(request: TransferRequest<'_>) -> Result<TransferRun, MatchError> {
    let TransferRequest { from, onto, values, mut masked, run_mask, max_distance, diagonal } = request;
    let n = from.n_vertices();
    let given = match &values {
        TransferValues::Map(v) => v.len(),
        TransferValues::Keys(k) => k.len(),
    };
    if given != n {
        return Err(MatchError::InvalidInput(format!("a transfer of {given} values from a surface of {n} vertices")));
    }
    if masked.len() != n {
        return Err(MatchError::InvalidInput(format!(
            "a transfer's mask has {} entries for a surface of {n} vertices",
            masked.len()
        )));
    }
    // The registration's own mask of the giving surface: its values did
    // not count in the match (and may be a placeholder such as
    // FreeSurfer's 0 on the medial wall).
    let own = from.mask().filter(|_| run_mask);
    for (m, w) in masked.iter_mut().zip(own.unwrap_or(&[])) {
        *m |= *w < 0.5;
    }
    let correspondence = Correspondence::new(from, onto)?;
    let beyond = |c: &Correspondence| Carried {
        vertices: c.len(),
        beyond: c.distances().iter().filter(|&&d| d.is_nan() || d > max_distance).count(),
        missing: 0,
    };
    let (values, carried) = match values {
        TransferValues::Keys(keys) => {
            let keys: Vec<i32> = keys.iter().zip(&masked).map(|(&k, &m)| if m { -1 } else { k }).collect();
            (TransferValues::Keys(correspondence.labels(&keys, max_distance)?), beyond(&correspondence))
        }
        TransferValues::Map(map) => {
            let map: Vec<f64> = map.iter().zip(&masked).map(|(&v, &m)| if m { f64::NAN } else { v }).collect();
            let (out, carried) = correspondence.map(&map, max_distance)?;
            (TransferValues::Map(out), carried)
        }
    };
    let mut d: Vec<f64> = correspondence.distances().iter().map(|d| 100.0 * d / diagonal).collect();
    d.sort_by(f64::total_cmp);
    let at = |q: f64| d.get(((d.len() as f64 - 1.0) * q).round() as usize).copied().unwrap_or(0.0);
    Ok(TransferRun {
        values,
        carried,
        masked: masked.iter().filter(|m| **m).count(),
        run_mask: own.is_some(),
        distance_percent: [at(0.5), at(0.95), at(1.0)],
    })
}

#[cfg(test)]
mod tests {
    use fshape_mesh::generate::icosphere;

    use super::*;

    /// A surface onto itself: every value comes back where it was, except
    /// from the vertices either mask leaves out.
    #[test]
    fn onto_itself_each_value_comes_back_but_the_masked_ones() {
        let sphere = icosphere(2, 1.0);
        let n = sphere.n_vertices();
        let own: Vec<f64> = (0..n).map(|v| if v % 7 == 0 { 0.0 } else { 1.0 }).collect();
        let from = sphere.clone().with_signal_and_mask(Some(vec![0.0; n]), Some(own)).unwrap();
        let map: Vec<f64> = (0..n).map(|v| v as f64).collect();
        let masked: Vec<bool> = (0..n).map(|v| v % 5 == 0).collect();
        let request = |values: TransferValues, run_mask: bool| TransferRequest {
            from: &from,
            onto: &sphere,
            values,
            masked: masked.clone(),
            run_mask,
            max_distance: 1e-9,
            diagonal: 2.0,
        };
        let run = transfer(request(TransferValues::Map(map.clone()), true)).unwrap();
        let TransferValues::Map(out) = run.values else { panic!("a map gives a map") };
        for v in 0..n {
            let left_out = v % 5 == 0 || v % 7 == 0;
            assert!(if left_out { out[v].is_nan() } else { out[v] == map[v] }, "vertex {v}: {}", out[v]);
        }
        assert_eq!(run.masked, (0..n).filter(|v| v % 5 == 0 || v % 7 == 0).count());
        assert!(run.run_mask && run.distance_percent == [0.0; 3]);
        assert_eq!(run.carried, Carried { vertices: n, beyond: 0, missing: run.masked });
        // Keys, without the registration's mask.
        let keys: Vec<i32> = (0..n as i32).map(|v| v % 3).collect();
        let run = transfer(request(TransferValues::Keys(keys.clone()), false)).unwrap();
        let want: Vec<i32> = (0..n).map(|v| if v % 5 == 0 { -1 } else { keys[v] }).collect();
        assert_eq!(run.values, TransferValues::Keys(want));
        assert!(!run.run_mask);
        let mut wrong = request(TransferValues::Map(map.clone()), true);
        wrong.masked.pop();
        assert!(transfer(wrong).unwrap_err().to_string().contains("mask has"));
        let long: Vec<f64> = map.iter().chain([1.0].iter()).copied().collect();
        let e = transfer(request(TransferValues::Map(long), true)).unwrap_err().to_string();
        assert!(e.contains(&format!("{} values from a surface of {n} vertices", n + 1)), "{e}");
    }
}
