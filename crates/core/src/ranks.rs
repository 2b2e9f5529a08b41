//! How ranks talk: the two operations a z-slab decomposition needs, halo exchange with
//! the neighbours below and above, and an all-gather of small vectors (layer sums, flags).
//!
//! Solvers that run on ranks take `&(impl Communicator + ?Sized)` (so `&dyn Communicator`
//! works too: the trait is object safe, and [`SolveOptions::ranks`](crate::SolveOptions)
//! carries one); [`Alone`] is one rank, [`Threads`]
//! ranks as threads of one process (tests, and machines without MPI), and `lucent-mpi`'s
//! `Mpi` (feature `mpi`) ranks under `mpirun`. Every rank calls the operations in the same
//! sequence; a message that does not fit the caller's plan (a rank that stopped) comes
//! back empty or short, never as a hang: the callers check lengths and return an error.

use std::sync::Mutex;
use std::sync::mpsc::{Receiver, Sender, channel};

/// A group of ranks ordered 0..size along z (rank r's slab lies below rank r + 1's).
pub trait Communicator {
    /// This rank.
    fn rank(&self) -> usize;

    /// How many ranks.
    fn size(&self) -> usize;

    /// Sends `to_below` to rank − 1 and `to_above` to rank + 1 (nothing past the ends),
    /// runs `interior` while they travel, then receives what those neighbours sent: (from
    /// below, from above). Every rank calls it in the same sequence. [`exchange`] is the
    /// same with a closure that returns a value.
    fn exchange_around(
        &self,
        to_below: &[f64],
        to_above: &[f64],
        interior: &mut dyn FnMut(),
    ) -> (Vec<f64>, Vec<f64>);

    /// Every rank's `local`, concatenated in rank order, on every rank.
    fn all_gather(&self, local: &[f64]) -> Vec<f64>;
}

/// [`Communicator::exchange_around`] with an `interior` that returns a value: (from below,
/// from above, `interior`'s result).
pub fn exchange<R>(
    comm: &(impl Communicator + ?Sized),
    to_below: &[f64],
    to_above: &[f64],
    interior: impl FnOnce() -> R,
) -> (Vec<f64>, Vec<f64>, R) {
    let mut interior = Some(interior);
    let mut result = None;
    let (below, above) = comm.exchange_around(to_below, to_above, &mut || {
        if let Some(f) = interior.take() {
            result = Some(f());
        }
    });
    // `interior` ran (and left its result) or did not (and is still here): run it now.
    match (result, interior) {
        (Some(r), _) => (below, above, r),
        (None, Some(f)) => (below, above, f()),
        (None, None) => unreachable!("the closure takes `interior` only to store its result"),
    }
}

/// One rank alone: nothing to exchange.
#[derive(Debug, Clone, Copy, Default)]
pub struct Alone;

impl Communicator for Alone {
    fn rank(&self) -> usize {
        0
    }

    fn size(&self) -> usize {
        1
    }

    fn exchange_around(
        &self,
        _: &[f64],
        _: &[f64],
        interior: &mut dyn FnMut(),
    ) -> (Vec<f64>, Vec<f64>) {
        interior();
        (Vec::new(), Vec::new())
    }

    fn all_gather(&self, local: &[f64]) -> Vec<f64> {
        local.to_vec()
    }
}

/// What travels between in-process ranks: (kind, sequence number, sender, values).
type Message = (u8, u64, usize, Vec<f64>);

/// How long an in-process rank waits for a neighbour before it gives up on it.
const PATIENCE: std::time::Duration = std::time::Duration::from_secs(60);

const HALO: u8 = 0;
const GATHER: u8 = 1;

/// Ranks as threads of one process, connected by channels: the same protocol as MPI, for
/// tests and for running a decomposition without an MPI installation. `Send + Sync`, so a
/// rank can ride in `SolveOptions::ranks` as an MPI rank does (one thread uses it at a
/// time; the locks are uncontended).
#[derive(Debug)]
pub struct Threads {
    rank: usize,
    to: Vec<Sender<Message>>,
    /// The inbox and the messages that arrived before they were asked for.
    inbox: Mutex<(Receiver<Message>, Vec<Message>)>,
    sequence: Mutex<[u64; 2]>,
}

impl Threads {
    /// `size` connected ranks; hand one to each thread.
    pub fn world(size: usize) -> Vec<Threads> {
        let (senders, receivers): (Vec<_>, Vec<_>) = (0..size).map(|_| channel()).unzip();
        receivers
            .into_iter()
            .enumerate()
            .map(|(rank, inbox)| Threads {
                rank,
                to: senders.clone(),
                inbox: Mutex::new((inbox, Vec::new())),
                sequence: Mutex::new([0; 2]),
            })
            .collect()
    }

    /// Runs `f` on `size` connected ranks, one scoped thread each; every rank's result in
    /// rank order (`None` for a rank whose thread panicked).
    pub fn run<T: Send>(size: usize, f: impl Fn(&Threads) -> T + Sync) -> Vec<Option<T>> {
        let f = &f;
        std::thread::scope(|scope| {
            let handles: Vec<_> = Threads::world(size)
                .into_iter()
                .map(|comm| scope.spawn(move || f(&comm)))
                .collect();
            handles.into_iter().map(|h| h.join().ok()).collect()
        })
    }

    fn next(&self, kind: u8) -> u64 {
        let mut s = self.sequence.lock().unwrap_or_else(|p| p.into_inner());
        s[kind as usize] += 1;
        s[kind as usize]
    }

    fn send(&self, to: usize, kind: u8, sequence: u64, values: &[f64]) {
        // A rank that has gone (its thread ended) takes nothing more: ignore.
        let _ = self.to[to].send((kind, sequence, self.rank, values.to_vec()));
    }

    fn receive(&self, from: usize, kind: u8, sequence: u64) -> Vec<f64> {
        let matches = |m: &Message| m.0 == kind && m.1 == sequence && m.2 == from;
        let mut guard = self.inbox.lock().unwrap_or_else(|p| p.into_inner());
        let (inbox, early) = &mut *guard;
        if let Some(at) = early.iter().position(matches) {
            return early.swap_remove(at).3;
        }
        loop {
            match inbox.recv_timeout(PATIENCE) {
                Ok(m) if matches(&m) => return m.3,
                Ok(m) => early.push(m),
                // A rank that failed or panicked sends nothing more: the caller sees a
                // message that does not fit its plan (an error) instead of waiting forever.
                Err(_) => return Vec::new(),
            }
        }
    }
}

impl Communicator for Threads {
    fn rank(&self) -> usize {
        self.rank
    }

    fn size(&self) -> usize {
        self.to.len()
    }

    fn exchange_around(
        &self,
        to_below: &[f64],
        to_above: &[f64],
        interior: &mut dyn FnMut(),
    ) -> (Vec<f64>, Vec<f64>) {
        let sequence = self.next(HALO);
        let (below, above) = (
            self.rank.checked_sub(1),
            Some(self.rank + 1).filter(|&r| r < self.size()),
        );
        if let Some(b) = below {
            self.send(b, HALO, sequence, to_below);
        }
        if let Some(a) = above {
            self.send(a, HALO, sequence, to_above);
        }
        interior();
        let from_below = below.map_or_else(Vec::new, |b| self.receive(b, HALO, sequence));
        let from_above = above.map_or_else(Vec::new, |a| self.receive(a, HALO, sequence));
        (from_below, from_above)
    }

    fn all_gather(&self, local: &[f64]) -> Vec<f64> {
        let sequence = self.next(GATHER);
        for to in (0..self.size()).filter(|&r| r != self.rank) {
            self.send(to, GATHER, sequence, local);
        }
        let mut out = Vec::new();
        for from in 0..self.size() {
            if from == self.rank {
                out.extend_from_slice(local);
            } else {
                out.extend(self.receive(from, GATHER, sequence));
            }
        }
        out
    }
}
