//! How ranks talk: the operations a z-slab decomposition needs, halo exchange with the
//! neighbours below and above, an all-gather of small vectors (layer sums, flags), and
//! point-to-point messages among any ranks (a subset of ranks working on its own, and
//! moving a coarse level between subsets).
//!
//! Solvers that run on ranks take `&(impl Communicator + ?Sized)` (so `&dyn Communicator`
//! works too: the trait is object safe, and [`SolveOptions::ranks`](crate::SolveOptions)
//! carries one); [`Alone`] is one rank, [`Threads`]
//! ranks as threads of one process (tests, and machines without MPI), and `lucent-mpi`'s
//! `Mpi` (feature `mpi`) ranks under `mpirun`. Every rank calls the collective operations
//! in the same sequence, and every pair of ranks agrees on its point-to-point messages; a
//! message that does not fit the caller's plan (a rank that stopped) comes
//! back empty or short, never as a hang: the callers check lengths and return an error.

use std::sync::Mutex;

use crate::exact::ExactSum;
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

    /// Point to point among any ranks: sends each `(to, values)` of `sends`, runs
    /// `interior` while they travel, then receives one message from each rank of `from`,
    /// in that order. Only the ranks involved call it (a subset of ranks can work on its
    /// own), and the messages between two ranks arrive in the order they were sent, so
    /// each pair must agree on its sequence of messages. A rank that does not send what
    /// the plan says gives an empty or short message, not a hang.
    fn exchange_with(
        &self,
        sends: &[(usize, &[f64])],
        from: &[usize],
        interior: &mut dyn FnMut(),
    ) -> Vec<Vec<f64>>;
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

/// [`Communicator::exchange_with`] with an `interior` that returns a value: (one message
/// from each rank of `from`, `interior`'s result).
pub fn exchange_among<R>(
    comm: &(impl Communicator + ?Sized),
    sends: &[(usize, &[f64])],
    from: &[usize],
    interior: impl FnOnce() -> R,
) -> (Vec<Vec<f64>>, R) {
    let mut interior = Some(interior);
    let mut result = None;
    let received = comm.exchange_with(sends, from, &mut || {
        if let Some(f) = interior.take() {
            result = Some(f());
        }
    });
    match (result, interior) {
        (Some(r), _) => (received, r),
        (None, Some(f)) => (received, f()),
        (None, None) => unreachable!("the closure takes `interior` only to store its result"),
    }
}

/// Every rank's `local` combined into one vector, on every rank, by recursive doubling over
/// point-to-point messages ([`Communicator::exchange_with`]): each rank sends and receives
/// ⌈log₂ P⌉ messages of `local`'s length (two more on the ranks that fold in the ranks
/// beyond the largest power of two), where an all-gather hands every rank P of them.
/// `combine(acc, part)` folds another rank's (or group's) part into `acc` and must be
/// associative and commutative *exactly* (max, min, exact sums such as
/// [`crate::exact::ExactSum`]'s words), since ranks combine the parts in different orders;
/// it returns `false` for a part it cannot read. Every rank calls it in the same sequence.
/// `None` on every rank if any rank got a short message or a part `combine` refused (a
/// rank that left the protocol): the failure travels with the parts.
pub fn all_reduce(
    comm: &(impl Communicator + ?Sized),
    local: &[f64],
    combine: impl Fn(&mut [f64], &[f64]) -> bool,
) -> Option<Vec<f64>> {
    let (rank, size) = (comm.rank(), comm.size());
    if size <= 1 {
        return Some(local.to_vec());
    }
    // [failed, local...]: a failure anywhere reaches every rank like the parts do.
    let mut acc = Vec::with_capacity(local.len() + 1);
    acc.push(0.0);
    acc.extend_from_slice(local);
    let fold = |acc: &mut Vec<f64>, got: Vec<Vec<f64>>| {
        let part = got.into_iter().next().unwrap_or_default();
        let fits = part.len() == acc.len() && part[0] == 0.0 && combine(&mut acc[1..], &part[1..]);
        if !fits {
            acc[0] = 1.0;
        }
    };
    let send = |to: usize, values: &[f64]| {
        comm.exchange_with(&[(to, values)], &[], &mut || {});
    };
    let receive = |from: usize| comm.exchange_with(&[], &[from], &mut || {});
    // The largest power of two ≤ P: ranks beyond it fold into ranks 0, 1, … first and
    // take the result from them last.
    let p2 = 1usize << (usize::BITS - 1 - size.leading_zeros());
    if rank >= p2 {
        send(rank - p2, &acc);
        let got = receive(rank - p2).into_iter().next().unwrap_or_default();
        acc = if got.len() == acc.len() {
            got
        } else {
            let mut failed = acc;
            failed[0] = 1.0;
            failed
        };
    } else {
        if rank + p2 < size {
            let got = receive(rank + p2);
            fold(&mut acc, got);
        }
        let mut mask = 1;
        while mask < p2 {
            let partner = rank ^ mask;
            let got = comm.exchange_with(&[(partner, &acc)], &[partner], &mut || {});
            fold(&mut acc, got);
            mask <<= 1;
        }
        if rank + p2 < size {
            send(rank + p2, &acc);
        }
    }
    (acc[0] == 0.0).then(|| acc.split_off(1))
}

/// [`all_reduce`] of flags and exact sums, the reduction a solver's norms take: every
/// rank's `flags` or-ed (a clock that ran out, a cancel) and its `sums` merged, the same
/// on every rank and, since the sums are exact, the same bits however the terms were
/// spread over the ranks. `None` on every rank if any rank sent another shape (a rank
/// that left the protocol).
pub fn all_reduce_sums(
    comm: &(impl Communicator + ?Sized),
    flags: &[bool],
    sums: &[ExactSum],
) -> Option<(Vec<bool>, Vec<ExactSum>)> {
    let (f, words) = (flags.len(), ExactSum::WORDS);
    let mut local: Vec<f64> = flags.iter().map(|&b| f64::from(u8::from(b))).collect();
    for sum in sums {
        local.extend(sum.to_words());
    }
    let all = all_reduce(comm, &local, |acc, part| {
        if part.len() != acc.len() {
            return false;
        }
        for (a, p) in acc[..f].iter_mut().zip(&part[..f]) {
            *a = a.max(*p);
        }
        acc[f..]
            .chunks_mut(words)
            .zip(part[f..].chunks(words))
            .all(|(a, p)| ExactSum::merge_words(a, p))
    })
    .filter(|all| all.len() == local.len())?;
    let sums = all[f..]
        .chunks(words)
        .map(ExactSum::from_words)
        .collect::<Option<Vec<_>>>()?;
    Some((all[..f].iter().map(|&x| x != 0.0).collect(), sums))
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

    fn exchange_with(
        &self,
        sends: &[(usize, &[f64])],
        from: &[usize],
        interior: &mut dyn FnMut(),
    ) -> Vec<Vec<f64>> {
        // Rank 0 can only talk to itself: what it sends is what it receives, in order.
        let mut sent: Vec<Vec<f64>> = sends
            .iter()
            .filter(|(to, _)| *to == 0)
            .map(|(_, v)| v.to_vec())
            .collect();
        interior();
        sent.reverse();
        from.iter()
            .map(|&f| {
                if f == 0 {
                    sent.pop().unwrap_or_default()
                } else {
                    Vec::new()
                }
            })
            .collect()
    }
}

/// What travels between in-process ranks: (kind, sequence number, sender, values).
type Message = (u8, u64, usize, Vec<f64>);

/// How long an in-process rank waits for a neighbour before it gives up on it.
const PATIENCE: std::time::Duration = std::time::Duration::from_secs(60);

const HALO: u8 = 0;
const GATHER: u8 = 1;
/// Point to point: numbered per pair of ranks, not per call.
const POINT: u8 = 2;

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
    /// Point-to-point messages sent to and received from each rank so far.
    pairs: Mutex<(Vec<u64>, Vec<u64>)>,
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
                pairs: Mutex::new((vec![0; size], vec![0; size])),
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

    fn exchange_with(
        &self,
        sends: &[(usize, &[f64])],
        from: &[usize],
        interior: &mut dyn FnMut(),
    ) -> Vec<Vec<f64>> {
        let lock = || self.pairs.lock().unwrap_or_else(|p| p.into_inner());
        {
            let mut pairs = lock();
            for &(to, values) in sends {
                if to < self.size() {
                    pairs.0[to] += 1;
                    self.send(to, POINT, pairs.0[to], values);
                }
            }
        }
        interior();
        let mut pairs = lock();
        from.iter()
            .map(|&f| {
                if f >= self.size() {
                    return Vec::new();
                }
                pairs.1[f] += 1;
                self.receive(f, POINT, pairs.1[f])
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_to_point_among_a_subset_keeps_each_pairs_order() {
        // Ranks 0–2 of 4 trade among themselves (rank 3 takes no part) three times,
        // with a message to self, between two all-gathers of every rank; each pair's
        // messages arrive in the order sent, whatever the other ranks do meanwhile.
        let results = Threads::run(4, |comm| {
            let r = comm.rank();
            let before = comm.all_gather(&[r as f64]);
            let mut got = Vec::new();
            if r < 3 {
                for round in 0..3 {
                    let value = (10 * r + round) as f64;
                    let to: Vec<usize> = (0..3).collect();
                    let payloads: Vec<Vec<f64>> =
                        to.iter().map(|&q| vec![value, q as f64]).collect();
                    let sends: Vec<(usize, &[f64])> = to
                        .iter()
                        .zip(&payloads)
                        .map(|(&q, p)| (q, &p[..]))
                        .collect();
                    let mut ran = false;
                    let received = comm.exchange_with(&sends, &[2, 1, 0], &mut || ran = true);
                    assert!(ran);
                    got.push(received);
                }
            }
            let after = comm.all_gather(&[-(r as f64)]);
            (before, got, after)
        });
        for (r, result) in results.into_iter().enumerate() {
            let (before, got, after) = result.unwrap();
            assert_eq!(before, [0.0, 1.0, 2.0, 3.0]);
            assert_eq!(after, [0.0, -1.0, -2.0, -3.0]);
            if r == 3 {
                assert!(got.is_empty());
                continue;
            }
            for (round, received) in got.iter().enumerate() {
                let expected: Vec<Vec<f64>> = [2, 1, 0]
                    .iter()
                    .map(|&q| vec![(10 * q + round) as f64, r as f64])
                    .collect();
                assert_eq!(received, &expected, "rank {r}, round {round}");
            }
        }
    }

    #[test]
    fn all_reduce_combines_every_rank_on_every_rank_count() {
        // Integers (exact in f64, so any order of addition gives the same sum) and a max:
        // every rank gets every rank's contribution once, on power-of-two rank counts and
        // on the others (which fold the ranks beyond the power of two in and out).
        for size in 1..=9 {
            let results = Threads::run(size, |comm| {
                let r = comm.rank() as f64;
                let out = all_reduce(comm, &[r + 1.0, r * r, -r], |acc, part| {
                    acc[0] += part[0];
                    acc[1] += part[1];
                    acc[2] = acc[2].max(part[2]);
                    true
                });
                // The same sequence again: the pairs' messages stay in step.
                let again = all_reduce(comm, &[1.0], |acc, part| {
                    acc[0] += part[0];
                    true
                });
                (out, again)
            });
            let n = size as f64;
            let expected = vec![
                n * (n + 1.0) / 2.0,
                (n - 1.0) * n * (2.0 * n - 1.0) / 6.0,
                0.0,
            ];
            for r in results {
                let (out, again) = r.unwrap();
                assert_eq!(out, Some(expected.clone()), "{size} ranks");
                assert_eq!(again, Some(vec![n]), "{size} ranks");
            }
        }
    }

    #[test]
    fn a_part_that_does_not_fit_fails_the_reduction_on_every_rank() {
        // Rank 2 of 5 (inside the power of two) and rank 4 (folded in) send a part of
        // another length: every rank returns None, none hangs.
        for odd in [2, 4] {
            let results = Threads::run(5, |comm| {
                let local = if comm.rank() == odd {
                    vec![1.0, 2.0, 3.0]
                } else {
                    vec![1.0, 2.0]
                };
                all_reduce(comm, &local, |acc, part| {
                    if part.len() != acc.len() {
                        return false;
                    }
                    acc[0] += part[0];
                    true
                })
            });
            for r in results {
                assert_eq!(r.unwrap(), None, "rank {odd} sent a longer part");
            }
        }
    }

    #[test]
    fn flags_and_exact_sums_reduce_to_the_same_bits_on_every_rank_count() {
        // Terms of wildly different sizes, spread over the ranks round robin: the merged sum
        // is the one-rank exact sum (a plain f64 sum of these terms depends on the order),
        // and a flag raised on one rank only reaches every rank.
        let terms: Vec<f64> = (0..40)
            .map(|i| (1.0 + f64::from(i) * 0.37) * 10f64.powi(i % 7 * 5 - 15))
            .collect();
        let whole: ExactSum = terms.iter().copied().collect();
        for size in 1..=7 {
            let results = Threads::run(size, |comm| {
                let r = comm.rank();
                let mine: ExactSum = terms.iter().skip(r).step_by(size).copied().collect();
                let squares: ExactSum = terms.iter().skip(r).step_by(size).map(|t| t * t).collect();
                all_reduce_sums(comm, &[r == size - 1, false], &[mine, squares])
            });
            for got in results {
                let (flags, sums) = got.unwrap().expect("every rank sent the same shape");
                assert_eq!(flags, [true, false], "{size} ranks");
                assert_eq!(
                    sums[0].value().to_bits(),
                    whole.value().to_bits(),
                    "{size} ranks"
                );
                let squares: ExactSum = terms.iter().map(|t| t * t).collect();
                assert_eq!(sums[1].value().to_bits(), squares.value().to_bits());
            }
        }
        // One rank with one sum fewer: None everywhere, no hang.
        let results = Threads::run(3, |comm| {
            let sums = vec![ExactSum::new(); if comm.rank() == 1 { 1 } else { 2 }];
            all_reduce_sums(comm, &[false], &sums)
        });
        for got in results {
            assert!(got.unwrap().is_none());
        }
    }

    #[test]
    fn alone_receives_what_it_sent_itself_in_order() {
        let (a, b) = ([1.0, 2.0], [3.0]);
        let got = Alone.exchange_with(&[(0, &a), (0, &b)], &[0, 0, 0], &mut || ());
        assert_eq!(got, vec![vec![1.0, 2.0], vec![3.0], vec![]]);
    }
}
