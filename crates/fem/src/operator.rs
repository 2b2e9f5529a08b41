//! The linear-operator trait the iterative solvers are written against, once.

use rayon::prelude::*;

/// A square linear operator y = A x on f64 vectors.
pub trait LinearOperator: Sync {
    /// The dimension.
    fn dim(&self) -> usize;
    /// y = A x.
    fn apply(&self, x: &[f64], y: &mut [f64]);
}

impl LinearOperator for sprs::CsMat<f64> {
    fn dim(&self) -> usize {
        self.rows()
    }

    fn apply(&self, x: &[f64], y: &mut [f64]) {
        if self.is_csr() {
            y.par_iter_mut().enumerate().for_each(|(i, yi)| {
                *yi = self
                    .outer_view(i)
                    .map_or(0.0, |row| row.iter().map(|(j, v)| v * x[j]).sum());
            });
        } else {
            y.fill(0.0);
            for (j, col) in self.outer_iterator().enumerate() {
                for (i, v) in col.iter() {
                    y[i] += v * x[j];
                }
            }
        }
    }
}

/// A dense row-major matrix as an operator (small systems, tests).
#[derive(Debug, Clone, PartialEq)]
pub struct Dense {
    /// Dimension.
    pub n: usize,
    /// Row-major entries.
    pub data: Vec<f64>,
}

impl LinearOperator for Dense {
    fn dim(&self) -> usize {
        self.n
    }

    fn apply(&self, x: &[f64], y: &mut [f64]) {
        for (i, yi) in y.iter_mut().enumerate() {
            *yi = self.data[i * self.n..(i + 1) * self.n]
                .iter()
                .zip(x)
                .map(|(a, b)| a * b)
                .sum();
        }
    }
}

/// Σ aᵢbᵢ in a fixed order (the same bits on every run and thread count).
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    lucent_core::reduce::dot(a, b)
}

pub(crate) fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}
