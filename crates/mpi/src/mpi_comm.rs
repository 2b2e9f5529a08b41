//! [`Communicator`] over MPI (rsmpi): non-blocking sends overlapped with the caller's
//! interior work, and a variable-count all-gather.

use mpi::datatype::PartitionMut;
use mpi::topology::{Communicator as _, SimpleCommunicator};
use mpi::traits::*;

use lucent_core::ranks::Communicator;

/// The ranks of `MPI_COMM_WORLD`, in rank order along z.
///
/// Holds no MPI handle (each call takes the world's), so it is `Send + Sync` and can ride
/// in `SolveOptions::ranks` to the thread that runs the solve: initialise MPI with at
/// least `Threading::Serialized` (the ranks' calls come from one thread at a time, not
/// necessarily the main one), and keep the `Universe` alive while it is used.
#[derive(Debug, Clone, Copy)]
pub struct Mpi {
    rank: usize,
    size: usize,
}

impl Mpi {
    /// The world of an initialised MPI (`universe` is the proof, and must outlive the
    /// solves).
    pub fn world(universe: &mpi::environment::Universe) -> Self {
        let world = universe.world();
        Self {
            rank: world.rank() as usize,
            size: world.size() as usize,
        }
    }
}

/// An initialised MPI (finalised when dropped) and its world's ranks: what a program
/// under `mpirun` holds for its lifetime.
pub struct World {
    universe: mpi::environment::Universe,
}

/// Why MPI could not be started.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MpiError {
    /// `MPI_Init_thread` failed or MPI was initialised already.
    #[error("MPI could not be initialised (or was initialised already)")]
    Initialise,
    /// The library cannot take calls from a thread other than the main one.
    #[error(
        "this MPI offers {0:?} threading; lucent needs Serialized or Multiple (the solve runs on a pool thread)"
    )]
    Threading(mpi::Threading),
}

impl World {
    /// Initialises MPI with serialised threading (one thread calls MPI at a time, not
    /// necessarily the main one).
    ///
    /// A panic on any thread of this process, after the usual message, aborts every rank
    /// (`MPI_Abort`, exit status 101): unwinding would finalise MPI, a collective call that
    /// waits for the other ranks, which wait for this one, so the job would hang instead
    /// of failing.
    pub fn initialise() -> Result<Self, MpiError> {
        let (universe, threading) = mpi::initialize_with_threading(mpi::Threading::Serialized)
            .ok_or(MpiError::Initialise)?;
        if threading < mpi::Threading::Serialized {
            return Err(MpiError::Threading(threading));
        }
        let report = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            report(info);
            world().abort(101)
        }));
        Ok(Self { universe })
    }

    /// The world's ranks.
    pub fn ranks(&self) -> Mpi {
        Mpi::world(&self.universe)
    }

    /// Ends every rank's process with exit status `code` (`MPI_Abort`): for an error on
    /// this rank that the others may not share. Returning would finalise MPI, which
    /// waits for ranks that may be waiting for this one.
    pub fn abort(&self, code: i32) -> ! {
        world().abort(code)
    }
}

/// The tag of [`Communicator::exchange_with`]'s messages (the halo exchange's are 0), so
/// the two kinds never match each other's receives.
const POINT: mpi::Tag = 7;

fn world() -> SimpleCommunicator {
    SimpleCommunicator::world()
}

impl Communicator for Mpi {
    fn rank(&self) -> usize {
        self.rank
    }

    fn size(&self) -> usize {
        self.size
    }

    fn exchange_around(
        &self,
        to_below: &[f64],
        to_above: &[f64],
        interior: &mut dyn FnMut(),
    ) -> (Vec<f64>, Vec<f64>) {
        let rank = self.rank();
        let below = rank.checked_sub(1);
        let above = Some(rank + 1).filter(|&r| r < self.size());
        let world = world();
        mpi::request::scope(|scope| {
            let sent_below = below.map(|b| {
                world
                    .process_at_rank(b as i32)
                    .immediate_send(scope, to_below)
            });
            let sent_above = above.map(|a| {
                world
                    .process_at_rank(a as i32)
                    .immediate_send(scope, to_above)
            });
            // The interior rows need no halo: they run while the messages travel.
            interior();
            let from_below = below.map_or_else(Vec::new, |b| {
                world
                    .process_at_rank(b as i32)
                    .receive_vec_with_tag::<f64>(0)
                    .0
            });
            let from_above = above.map_or_else(Vec::new, |a| {
                world
                    .process_at_rank(a as i32)
                    .receive_vec_with_tag::<f64>(0)
                    .0
            });
            if let Some(request) = sent_below {
                request.wait();
            }
            if let Some(request) = sent_above {
                request.wait();
            }
            (from_below, from_above)
        })
    }

    fn all_gather(&self, local: &[f64]) -> Vec<f64> {
        let world = world();
        let size = self.size();
        let count = local.len() as i32;
        let mut counts = vec![0i32; size];
        world.all_gather_into(&count, &mut counts[..]);
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
            world.all_gather_varcount_into(local, &mut partition);
        }
        out
    }

    fn exchange_with(
        &self,
        sends: &[(usize, &[f64])],
        from: &[usize],
        interior: &mut dyn FnMut(),
    ) -> Vec<Vec<f64>> {
        let world = world();
        let size = self.size();
        mpi::request::scope(|scope| {
            let requests: Vec<_> = sends
                .iter()
                .filter(|(to, _)| *to < size)
                .map(|&(to, values)| {
                    world
                        .process_at_rank(to as i32)
                        .immediate_send_with_tag(scope, values, POINT)
                })
                .collect();
            interior();
            let received = from
                .iter()
                .map(|&f| {
                    if f < size {
                        world
                            .process_at_rank(f as i32)
                            .receive_vec_with_tag::<f64>(POINT)
                            .0
                    } else {
                        Vec::new()
                    }
                })
                .collect();
            for request in requests {
                request.wait();
            }
            received
        })
    }
}
