//! The processes of an MPI run (the `mpi` feature): `mpirun -n R fshape
//! atlas ...` shares the subjects among them (every process keeps the same
//! optimiser state; process 0 alone writes the checkpoint, the outputs and
//! the progress), `mpirun -n R fshape batch ...` deals the rows to them.

use mpi::datatype::PartitionMut;
use mpi::traits::{Communicator, CommunicatorCollectives};

/// MPI's world, and the universe that finalises MPI when dropped.
pub struct World {
    world: mpi::topology::SimpleCommunicator,
    _universe: std::rc::Rc<mpi::environment::Universe>,
}

impl fshape_match::Cluster for World {
    fn rank(&self) -> usize {
        self.world.rank() as usize
    }
    fn size(&self) -> usize {
        self.world.size() as usize
    }
    fn all_gather(&self, mine: &[f64]) -> Vec<f64> {
        let size = self.world.size() as usize;
        let count = mpi::Count::try_from(mine.len()).expect("a process's records fit MPI's count");
        let mut counts = vec![0 as mpi::Count; size];
        self.world.all_gather_into(&count, &mut counts[..]);
        let displs: Vec<mpi::Count> = counts
            .iter()
            .scan(0 as mpi::Count, |acc, &c| {
                let at = *acc;
                *acc += c;
                Some(at)
            })
            .collect();
        let total = counts.iter().map(|&c| c as usize).sum();
        let mut all = vec![0.0f64; total];
        let mut partition = PartitionMut::new(&mut all[..], counts, &displs[..]);
        self.world.all_gather_varcount_into(mine, &mut partition);
        all
    }
}

/// The world of this run: `None` for one process (no mpirun).
pub fn init() -> anyhow::Result<Option<(World, std::rc::Rc<mpi::environment::Universe>)>> {
    let universe = std::rc::Rc::new(
        mpi::initialize().ok_or_else(|| anyhow::anyhow!("MPI could not be initialised (or was already)"))?,
    );
    let world = universe.world();
    if world.size() <= 1 {
        return Ok(None);
    }
    Ok(Some((World { world, _universe: universe.clone() }, universe)))
}

/// Ends every process of the run (after an error on this one, which
/// the others would wait for forever).
pub fn abort(universe: &mpi::environment::Universe) -> ! {
    universe.world().abort(1)
}

/// Waits for every process (collective).
pub fn barrier(universe: &mpi::environment::Universe) {
    universe.world().barrier();
}
