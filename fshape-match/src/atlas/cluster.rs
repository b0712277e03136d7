//! The processes an atlas's subjects are shared among (MPI ranks, say).

/// The processes an atlas's subjects are shared among (MPI ranks, say):
/// process r evaluates the subjects of [`Cluster::subjects`]`(r)`, a
/// contiguous block, and every process gathers every subject's terms in
/// subject order and sums them itself, so that J, its gradient and the
/// optimiser's state are the same bits on every process, and the same as
/// on one process, for any number of processes. The default is one
/// process ([`Local`]).
pub trait Cluster {
    /// This process's index, from 0.
    fn rank(&self) -> usize;
    /// The number of processes.
    fn size(&self) -> usize;
    /// Collective: every process's `mine`, concatenated in rank order.
    fn all_gather(&self, mine: &[f64]) -> Vec<f64>;
    /// The subjects (of `n`) process `rank` evaluates: contiguous blocks
    /// in order, of sizes differing by at most one.
    fn subjects(&self, rank: usize, n: usize) -> std::ops::Range<usize> {
        let size = self.size().max(1);
        rank * n / size..(rank + 1) * n / size
    }
}

/// One process: gathering is the identity.
#[derive(Clone, Copy, Debug, Default)]
pub struct Local;

impl Cluster for Local {
    fn rank(&self) -> usize {
        0
    }
    fn size(&self) -> usize {
        1
    }
    fn all_gather(&self, mine: &[f64]) -> Vec<f64> {
        mine.to_vec()
    }
}
