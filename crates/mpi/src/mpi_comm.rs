//! [`Communicator`] over MPI (rsmpi): non-blocking sends overlapped with the caller's
//! interior work, and a variable-count all-gather.

use mpi::datatype::PartitionMut;
use mpi::topology::{Communicator as _, SimpleCommunicator};
use mpi::traits::*;

use lucent_core::ranks::Communicator;

/// The ranks of an MPI communicator (normally `universe.world()`), in rank order along z.
pub struct Mpi {
    world: SimpleCommunicator,
}

impl Mpi {
    /// Ranks of `world`.
    pub fn new(world: SimpleCommunicator) -> Self {
        Self { world }
    }
}

impl Communicator for Mpi {
    fn rank(&self) -> usize {
        self.world.rank() as usize
    }

    fn size(&self) -> usize {
        self.world.size() as usize
    }

    fn exchange<R>(
        &self,
        to_below: &[f64],
        to_above: &[f64],
        interior: impl FnOnce() -> R,
    ) -> (Vec<f64>, Vec<f64>, R) {
        let rank = self.rank();
        let below = rank.checked_sub(1);
        let above = Some(rank + 1).filter(|&r| r < self.size());
        mpi::request::scope(|scope| {
            let sent_below = below.map(|b| {
                self.world
                    .process_at_rank(b as i32)
                    .immediate_send(scope, to_below)
            });
            let sent_above = above.map(|a| {
                self.world
                    .process_at_rank(a as i32)
                    .immediate_send(scope, to_above)
            });
            // The interior rows need no halo: they run while the messages travel.
            let result = interior();
            let from_below = below.map_or_else(Vec::new, |b| {
                self.world.process_at_rank(b as i32).receive_vec::<f64>().0
            });
            let from_above = above.map_or_else(Vec::new, |a| {
                self.world.process_at_rank(a as i32).receive_vec::<f64>().0
            });
            if let Some(request) = sent_below {
                request.wait();
            }
            if let Some(request) = sent_above {
                request.wait();
            }
            (from_below, from_above, result)
        })
    }

    fn all_gather(&self, local: &[f64]) -> Vec<f64> {
        let size = self.size();
        let count = local.len() as i32;
        let mut counts = vec![0i32; size];
        self.world.all_gather_into(&count, &mut counts[..]);
        let displacements: Vec<i32> = counts
            .iter()
            .scan(0, |at, &c| {
                let here = *at;
                *at += c;
                Some(here)
            })
            .collect();
        let total: i32 = counts.iter().sum();
        let mut out = vec![0.0f64; total as usize];
        {
            let mut partition = PartitionMut::new(&mut out[..], &counts[..], &displacements[..]);
            self.world.all_gather_varcount_into(local, &mut partition);
        }
        out
    }
}
