//! Sums in a fixed order, so that a solve's norms and inner products — and with them its
//! stopping decisions and Krylov coefficients — are the same bits on every run, thread
//! count and build.
//!
//! Rayon's `par_iter().sum()` adds in an order its work stealing picks at run time: two
//! runs of one program on one machine can differ in the last bits, and a residual that
//! lands either side of a tolerance changes the iteration count. Here the terms are cut
//! into blocks of [`BLOCK`] that never depend on the thread count, each block is summed
//! left to right (in parallel across blocks), and the block sums are added left to right.

use rayon::prelude::*;

/// Terms per block: a block's sequential sum is long enough to hide the parallel
/// overhead and short enough that 2²⁰ terms make 256 blocks for the threads.
pub const BLOCK: usize = 4096;

/// Σ `term(i)` over `0..len` in the fixed order above (f64 throughout).
pub fn sum(len: usize, term: impl Fn(usize) -> f64 + Sync) -> f64 {
    let block = |b: usize| -> f64 {
        let end = ((b + 1) * BLOCK).min(len);
        (b * BLOCK..end).map(&term).sum()
    };
    let blocks = len.div_ceil(BLOCK);
    if blocks <= 4 {
        return (0..blocks).map(block).sum();
    }
    let partial: Vec<f64> = (0..blocks).into_par_iter().map(block).collect();
    partial.iter().sum()
}

/// Σ aᵢbᵢ in f64, in the fixed order of [`sum`].
pub fn dot<A, B>(a: &[A], b: &[B]) -> f64
where
    A: Copy + Into<f64> + Sync,
    B: Copy + Into<f64> + Sync,
{
    debug_assert_eq!(a.len(), b.len());
    sum(a.len().min(b.len()), |i| a[i].into() * b[i].into())
}

/// ‖x‖₂ in f64, in the fixed order of [`sum`].
pub fn norm2<T: Copy + Into<f64> + Sync>(x: &[T]) -> f64 {
    sum(x.len(), |i| {
        let v: f64 = x[i].into();
        v * v
    })
    .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same bits on pools of 1, 2 and 7 threads, run after run, and the block order
    /// written out by hand.
    #[test]
    fn sums_do_not_depend_on_the_threads() {
        let n = 100_003;
        let x: Vec<f64> = (0..n)
            .map(|i| ((i * 7919) % 1000) as f64 * 1e-3 + 1e-9 * i as f64)
            .collect();
        let by_hand = x
            .chunks(BLOCK)
            .map(|c| c.iter().map(|v| v * v).sum::<f64>())
            .fold(0.0, |a, s| a + s);
        let on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a pool")
                .install(|| dot(&x, &x))
        };
        for threads in [1, 2, 7, 2, 1] {
            assert_eq!(on(threads).to_bits(), by_hand.to_bits());
        }
        assert_eq!(norm2(&x).to_bits(), by_hand.sqrt().to_bits());
        // Short vectors: the same block order without the pool.
        assert_eq!(sum(3, |i| i as f64), 3.0);
        assert_eq!(sum(0, |_| 1.0), 0.0);
    }
}
