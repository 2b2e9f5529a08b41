//! Sums of f64 that do not depend on the order of their terms: [`ExactSum`] keeps the
//! exact sum of every finite f64 added to it as a fixed-point integer (a Kulisch
//! accumulator: 2^-1074, the smallest subnormal, is its unit; 68 digits of 32 bits, the
//! top one signed, hold the sum of up to 2^99 terms of any finite size), and rounds
//! once, to nearest, when asked.
//!
//! Norms on ranks use it to be bitwise reproducible whatever the decomposition: each rank
//! adds its partial sums, the ranks exchange their accumulators as words
//! ([`ExactSum::to_words`], integers below 2^32, exact in f64) and merge them in any
//! order. Only the partial sums themselves (each a plain left-to-right f64 sum over a
//! fixed run of cells) are rounded, so the result depends on where those runs begin and
//! end, never on which rank holds them, nor on the order of the merge (Demmel & Nguyen,
//! "Parallel reproducible summation", IEEE TC 2015, reach the same end with fewer bits).
//!
//! Non-finite terms: any NaN, or +∞ and −∞ together, make the sum NaN; otherwise an ∞
//! term makes it that ∞. A finite exact sum beyond f64's range rounds to ±∞.

/// Cells along x in one run of a grid norm: ‖v‖² is Σ over runs of (Σ v² over the run,
/// left to right), the run sums added exactly ([`ExactSum`]). A run is one x-line's cells
/// [8k, 8k + 8) (the last one of a line shorter). A decomposition whose boxes start in x
/// at multiples of this (z-slabs, y-slabs and boxes cut so) sums whole runs on each rank,
/// and one rank and many give the same bits: the blocking factor of AMReX, for
/// reproducibility instead of coarsening.
pub const NORM_RUN: usize = 8;

/// Adds Σ v² of `lines` (whole x-lines `nx` cells long, one after another) to `sum`: each
/// line cut into runs of [`NORM_RUN`], each run summed left to right in f64, the run sums
/// added exactly.
pub fn add_run_squares(lines: &[f64], nx: usize, sum: &mut ExactSum) {
    for line in lines.chunks(nx.max(1)) {
        sum.extend(
            line.chunks(NORM_RUN)
                .map(|run| run.iter().map(|x| x * x).sum::<f64>()),
        );
    }
}

/// Digits of 32 bits; digit k weighs 2^(32k − 1074).
const DIGITS: usize = 68;
/// Additions between carry propagations (each adds below 2^32 to three digits of i64).
const LAZY: u32 = 1 << 30;

/// An exact, order-independent sum of f64 (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExactSum {
    digits: [i64; DIGITS],
    /// Additions since the digits were last brought below 2^32.
    pending: u32,
    nan: bool,
    positive_infinity: bool,
    negative_infinity: bool,
}

impl Default for ExactSum {
    fn default() -> Self {
        Self::new()
    }
}

impl ExactSum {
    /// How many words [`ExactSum::to_words`] gives.
    pub const WORDS: usize = DIGITS + 1;

    /// Zero.
    pub fn new() -> Self {
        Self {
            digits: [0; DIGITS],
            pending: 0,
            nan: false,
            positive_infinity: false,
            negative_infinity: false,
        }
    }

    /// Adds `x` exactly.
    pub fn add(&mut self, x: f64) {
        if !x.is_finite() {
            self.nan |= x.is_nan();
            self.positive_infinity |= x == f64::INFINITY;
            self.negative_infinity |= x == f64::NEG_INFINITY;
            return;
        }
        let bits = x.to_bits();
        let exponent = ((bits >> 52) & 0x7ff) as usize;
        let fraction = bits & ((1 << 52) - 1);
        // x = mantissa · 2^(offset − 1074).
        let (mantissa, offset) = if exponent == 0 {
            (fraction, 0)
        } else {
            (fraction | (1 << 52), exponent - 1)
        };
        if mantissa == 0 {
            return;
        }
        if self.pending >= LAZY {
            self.normalize();
        }
        self.pending += 1;
        let (digit, shift) = (offset / 32, offset % 32);
        let wide = u128::from(mantissa) << shift;
        let sign = if x < 0.0 { -1 } else { 1 };
        for k in 0..3 {
            let part = ((wide >> (32 * k)) & 0xffff_ffff) as i64;
            self.digits[digit + k] += sign * part;
        }
    }

    /// Adds every term of `other` (exactly: merging in any order gives the same sum).
    pub fn merge(&mut self, other: &Self) {
        let mut other = other.clone();
        other.normalize();
        if self.pending >= LAZY {
            self.normalize();
        }
        self.pending += 1;
        for (d, o) in self.digits.iter_mut().zip(other.digits) {
            *d += o;
        }
        self.nan |= other.nan;
        self.positive_infinity |= other.positive_infinity;
        self.negative_infinity |= other.negative_infinity;
    }

    /// Propagates carries: every digit but the last in [0, 2^32), the last signed.
    fn normalize(&mut self) {
        let mut carry = 0i64;
        for d in &mut self.digits[..DIGITS - 1] {
            let v = *d + carry;
            carry = v >> 32;
            *d = v - (carry << 32);
        }
        self.digits[DIGITS - 1] += carry;
        self.pending = 0;
    }

    /// The sum rounded to the nearest f64 (ties to even; in the subnormal range it may be
    /// rounded twice, still a function of the exact sum alone).
    pub fn value(&self) -> f64 {
        if self.nan || (self.positive_infinity && self.negative_infinity) {
            return f64::NAN;
        }
        if self.positive_infinity {
            return f64::INFINITY;
        }
        if self.negative_infinity {
            return f64::NEG_INFINITY;
        }
        let mut sum = self.clone();
        sum.normalize();
        let negative = sum.digits[DIGITS - 1] < 0;
        if negative {
            for d in &mut sum.digits {
                *d = -*d;
            }
            sum.normalize();
        }
        let Some(top) = sum.digits.iter().rposition(|&d| d != 0) else {
            return 0.0;
        };
        // Digit 65 starts at 2^1006; from digit 66 (2^1038) on, beyond f64's range.
        let magnitude = if top >= 66 {
            f64::INFINITY
        } else {
            // The top three digits (at least 65 significant bits), and a sticky bit for
            // anything below them, round correctly in one conversion.
            let low = top.saturating_sub(2);
            let mut window = 0u128;
            for k in (low..=top).rev() {
                window = (window << 32) | sum.digits[k] as u128;
            }
            if sum.digits[..low].iter().any(|&d| d != 0) {
                window |= 1;
            }
            window as f64 * power_of_two(32 * low as i32 - 1074)
        };
        if negative { -magnitude } else { magnitude }
    }

    /// The sum as [`ExactSum::WORDS`] f64 words, each an integer of magnitude below 2^53
    /// (exact), to send between ranks; [`ExactSum::from_words`] reads them back.
    pub fn to_words(&self) -> Vec<f64> {
        let mut sum = self.clone();
        sum.normalize();
        let mut words: Vec<f64> = sum.digits.iter().map(|&d| d as f64).collect();
        words.push(f64::from(
            u8::from(self.nan)
                | (u8::from(self.positive_infinity) << 1)
                | (u8::from(self.negative_infinity) << 2),
        ));
        words
    }

    /// Adds the sum the words `part` hold into the sum `words` hold, in place (both as
    /// [`ExactSum::to_words`] writes them): the combining step of an all-reduce
    /// ([`crate::ranks::all_reduce`]), exact, so the parts may meet in any order. `false`,
    /// and `words` unchanged, if either is not words `to_words` could have written.
    pub fn merge_words(words: &mut [f64], part: &[f64]) -> bool {
        match (Self::from_words(words), Self::from_words(part)) {
            (Some(mut sum), Some(other)) => {
                sum.merge(&other);
                words.copy_from_slice(&sum.to_words());
                true
            }
            _ => false,
        }
    }

    /// The sum [`ExactSum::to_words`] wrote, or `None` for words it cannot have written.
    pub fn from_words(words: &[f64]) -> Option<Self> {
        if words.len() != Self::WORDS || words.iter().any(|w| w.fract() != 0.0) {
            return None;
        }
        let mut sum = Self::new();
        for (k, (d, &w)) in sum.digits.iter_mut().zip(words).enumerate() {
            let in_range = if k + 1 < DIGITS {
                (0.0..4_294_967_296.0).contains(&w)
            } else {
                w.abs() < 9_007_199_254_740_992.0
            };
            if !in_range {
                return None;
            }
            *d = w as i64;
        }
        let flags = words[DIGITS];
        if !(0.0..8.0).contains(&flags) {
            return None;
        }
        let flags = flags as u8;
        sum.nan = flags & 1 != 0;
        sum.positive_infinity = flags & 2 != 0;
        sum.negative_infinity = flags & 4 != 0;
        Some(sum)
    }
}

impl Extend<f64> for ExactSum {
    fn extend<I: IntoIterator<Item = f64>>(&mut self, terms: I) {
        for x in terms {
            self.add(x);
        }
    }
}

impl FromIterator<f64> for ExactSum {
    fn from_iter<I: IntoIterator<Item = f64>>(terms: I) -> Self {
        let mut sum = Self::new();
        sum.extend(terms);
        sum
    }
}

/// 2^k for k in [−1074, 1023], exactly.
fn power_of_two(k: i32) -> f64 {
    debug_assert!((-1074..=1023).contains(&k));
    if k >= -1022 {
        f64::from_bits(((k + 1023) as u64) << 52)
    } else {
        f64::from_bits(1u64 << (k + 1074))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn exact(terms: &[f64]) -> f64 {
        terms.iter().copied().collect::<ExactSum>().value()
    }

    #[test]
    fn merged_words_are_the_sum_of_both_and_bad_words_are_refused() {
        let a: ExactSum = [1e16, 1.0, 0.25].into_iter().collect();
        let b: ExactSum = [-1e16, 3e-300].into_iter().collect();
        let mut words = a.to_words();
        assert!(ExactSum::merge_words(&mut words, &b.to_words()));
        let merged = ExactSum::from_words(&words).unwrap();
        assert_eq!(merged.value().to_bits(), (1.25 + 3e-300f64).to_bits());
        // Words it could not have written (a fraction, a digit out of range, too few)
        // leave the target as it was.
        let before = words.clone();
        let mut bad = b.to_words();
        bad[3] = 0.5;
        assert!(!ExactSum::merge_words(&mut words, &bad));
        bad[3] = 5e9;
        assert!(!ExactSum::merge_words(&mut words, &bad));
        assert!(!ExactSum::merge_words(&mut words, &bad[1..]));
        assert_eq!(words, before);
    }

    #[test]
    fn cancellation_and_the_range_ends_are_exact() {
        assert_eq!(exact(&[1e16, 1.0, -1e16]), 1.0);
        assert_eq!(exact(&[1e300, 1e-300, -1e300]), 1e-300);
        assert_eq!(exact(&[f64::MAX, f64::MAX, -f64::MAX]), f64::MAX);
        assert_eq!(exact(&[f64::MAX, f64::MAX]), f64::INFINITY);
        assert_eq!(exact(&[-f64::MAX, -f64::MAX]), f64::NEG_INFINITY);
        let tiny = f64::from_bits(1);
        assert_eq!(exact(&[tiny, tiny, tiny]), 3.0 * tiny);
        assert_eq!(exact(&[0.1, 0.2, -0.3]), {
            // 0.1 + 0.2 − 0.3 in exact arithmetic on the three doubles: 2^-55 + 2^-57…
            // computed here with two error-free additions.
            let (s, e) = two_sum(0.1, 0.2);
            let (t, f) = two_sum(s, -0.3);
            t + (e + f)
        });
        assert_eq!(exact(&[]), 0.0);
        assert_eq!(exact(&[-2.5]), -2.5);
        // Ties round to even: 2^53 + 1 is halfway between 2^53 and 2^53 + 2.
        assert_eq!(
            exact(&[9_007_199_254_740_992.0, 1.0]),
            9_007_199_254_740_992.0
        );
        assert_eq!(
            exact(&[9_007_199_254_740_992.0, 1.0, 1e-300]),
            9_007_199_254_740_994.0
        );
    }

    fn two_sum(a: f64, b: f64) -> (f64, f64) {
        let s = a + b;
        let v = s - a;
        (s, (a - (s - v)) + (b - v))
    }

    #[test]
    fn non_finite_terms_follow_ieee() {
        assert!(exact(&[1.0, f64::NAN]).is_nan());
        assert!(exact(&[f64::INFINITY, f64::NEG_INFINITY]).is_nan());
        assert_eq!(exact(&[f64::INFINITY, -1e308, 2.0]), f64::INFINITY);
        assert_eq!(exact(&[f64::NEG_INFINITY, 1e308]), f64::NEG_INFINITY);
    }

    #[test]
    fn words_that_were_not_written_are_refused() {
        let words = ExactSum::from_iter([3.0, -1e-20]).to_words();
        assert!(ExactSum::from_words(&words[1..]).is_none());
        let mut bad = words.clone();
        bad[3] = 0.5;
        assert!(ExactSum::from_words(&bad).is_none());
        bad[3] = 4_294_967_296.0;
        assert!(ExactSum::from_words(&bad).is_none());
        bad = words;
        bad[ExactSum::WORDS - 1] = 9.0;
        assert!(ExactSum::from_words(&bad).is_none());
    }

    fn term() -> impl Strategy<Value = f64> {
        prop_oneof![
            -1e6..1e6f64,
            (-30i32..30, -1.0..1.0f64).prop_map(|(e, m)| m * 10f64.powi(e)),
            any::<f64>().prop_filter("finite", |x| x.is_finite()),
        ]
    }

    proptest! {
        /// Any order and any split into merged parts give the same bits; the value is the
        /// correctly rounded sum (checked against a sum of the terms sorted by magnitude with
        /// error-free transformations, which is exact to a few ulp for these ranges).
        #[test]
        fn order_and_splits_do_not_change_the_bits(
            mut terms in prop::collection::vec(term(), 0..200),
            cut in 0usize..200,
            seed in any::<u64>(),
        ) {
            let whole = exact(&terms);
            let cut = cut.min(terms.len());
            let mut left: ExactSum = terms[..cut].iter().copied().collect();
            let right: ExactSum = terms[cut..].iter().copied().collect();
            left.merge(&right);
            prop_assert_eq!(left.value().to_bits(), whole.to_bits());
            let words = left.to_words();
            let back = ExactSum::from_words(&words).unwrap();
            prop_assert_eq!(back.value().to_bits(), whole.to_bits());
            // A shuffle (a fixed permutation from the seed).
            let mut state = seed | 1;
            for i in (1..terms.len()).rev() {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                terms.swap(i, (state % (i as u64 + 1)) as usize);
            }
            prop_assert_eq!(exact(&terms).to_bits(), whole.to_bits());
            // Against a compensated sum, where that sum is finite and exact enough.
            let mut reference = (0.0f64, 0.0f64);
            let mut sorted = terms.clone();
            sorted.sort_by(|a, b| a.abs().total_cmp(&b.abs()));
            for x in sorted {
                let (s, e) = two_sum(reference.0, x);
                reference = (s, reference.1 + e);
            }
            let compensated = reference.0 + reference.1;
            if compensated.is_finite() && whole.is_finite() {
                // Both within an ulp or so of the exact sum, plus the compensated sum's
                // second-order term n²u²Σ|x| (negligible at n ≤ 200).
                let scale: f64 = terms.iter().map(|x| x.abs()).sum();
                prop_assert!((whole - compensated).abs() <= 1e-15 * scale + f64::MIN_POSITIVE,
                    "exact {whole} against compensated {compensated}");
            }
        }
    }
}
