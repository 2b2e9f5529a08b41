//! The regular grid the explicit schemes run on: cell-centred, one spacing h on all axes
//! (the papers' Δ, Δx), f64 fields indexed i + nx (j + ny k).

use glam::DVec3;
use rayon::prelude::*;

use crate::error::ExplicitError;

/// A cell-centred grid of `dims` cells of side `spacing` (length), its low corner at
/// `origin`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lattice {
    /// Cells per axis.
    pub dims: [usize; 3],
    /// Cell side (length).
    pub spacing: f64,
    /// Low corner (length).
    pub origin: DVec3,
}

impl Lattice {
    /// A grid with its low corner at the origin.
    pub fn new(dims: [usize; 3], spacing: f64) -> Result<Self, ExplicitError> {
        if dims.contains(&0) || !(spacing.is_finite() && spacing > 0.0) {
            return Err(ExplicitError::Invalid(format!(
                "lattice of {dims:?} cells of side {spacing}: need cells on every axis and a positive side"
            )));
        }
        Ok(Self {
            dims,
            spacing,
            origin: DVec3::ZERO,
        })
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.dims.iter().product()
    }

    /// Never empty (checked at construction); here for clippy's `len_without_is_empty`.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Index strides along x, y, z.
    pub fn strides(&self) -> [usize; 3] {
        [1, self.dims[0], self.dims[0] * self.dims[1]]
    }

    /// (i, j, k) of cell `c`.
    pub fn coords(&self, c: usize) -> [usize; 3] {
        let [nx, ny, _] = self.dims;
        [c % nx, (c / nx) % ny, c / (nx * ny)]
    }

    /// Centre of cell (i, j, k), allowing one ghost layer (−1 and n) on each side.
    pub fn centre(&self, at: [isize; 3]) -> DVec3 {
        self.origin + (DVec3::new(at[0] as f64, at[1] as f64, at[2] as f64) + 0.5) * self.spacing
    }

    /// Checks that a field has one value per cell, all finite.
    pub(crate) fn check_field(&self, name: &str, field: &[f64]) -> Result<(), ExplicitError> {
        if field.len() != self.len() {
            return Err(ExplicitError::Invalid(format!(
                "{name}: {} values for {} cells",
                field.len(),
                self.len()
            )));
        }
        if let Some((c, v)) = field.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(ExplicitError::Invalid(format!("{name}: {v} in cell {c}")));
        }
        Ok(())
    }
}

/// The growth monitor every explicit march runs: stops a run whose largest value has grown
/// beyond `factor` times its reference, or that is no longer finite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GrowthMonitor {
    /// The size a stable run cannot exceed by much: the initial field, the sources over
    /// the run, the boundary values.
    pub reference: f64,
    /// How far beyond `reference` counts as diverging (the schemes use 10⁶).
    pub factor: f64,
}

impl GrowthMonitor {
    /// `Some(reason)` if the run must stop. In parallel over blocks of the field: the
    /// largest magnitude (NaN or ∞ where any value is not finite) does not depend on the
    /// order, so neither does the verdict.
    pub fn check(&self, field: &[f64], iteration: usize) -> Option<lucent_core::StopReason> {
        let largest = field
            .par_chunks(1 << 14)
            .map(|block| {
                block.iter().fold(0.0f64, |largest, v| {
                    if v.is_finite() {
                        largest.max(v.abs())
                    } else {
                        f64::INFINITY
                    }
                })
            })
            .reduce(|| 0.0, f64::max);
        self.check_largest(largest, iteration)
    }

    /// The same verdict from a field's largest magnitude alone (infinity or NaN for a
    /// field that is not finite): for fields reduced elsewhere, such as on a GPU.
    pub fn check_largest(&self, largest: f64, iteration: usize) -> Option<lucent_core::StopReason> {
        if !largest.is_finite() {
            return Some(lucent_core::StopReason::DivergedNonFinite { iteration });
        }
        let reference = self.reference.max(f64::MIN_POSITIVE);
        (largest > self.factor * reference).then(|| lucent_core::StopReason::DivergedGrowth {
            growth: largest / reference,
            iteration,
        })
    }
}
