//! Stability bounds of every scheme, as functions: what the papers state and what holds.
//!
//! Each bound is derived by von Neumann analysis on a periodic grid (the amplification
//! factor of every Fourier mode at most 1 in modulus) and, where the scheme's update is a
//! convex combination at small steps, by positivity (all stencil weights ≥ 0, which gives
//! a maximum principle). `cargo xtask stability` measures the blow-up boundary of each
//! scheme and draws it against these curves (`docs/stability.md`).

use glam::DVec3;

/// Murray's FTCS diffusion (Eq. 4.8, g = 0) in his parameters: β = D/Δ ∈ (0, 1],
/// albedo α ∈ [0, 1], r = cΔt/Δ.
pub mod ftcs_diffusion {
    /// The thesis's bound, Eq. 4.9: diagonal dominance with a worst-case β jump of 1 on
    /// every axis, r ≤ 6β / (72β² + 9β + 2(1 − α)). Safe, conservative by 2.2–3×.
    pub fn murray(beta: f64, albedo: f64) -> f64 {
        6.0 * beta / (72.0 * beta * beta + 9.0 * beta + 2.0 * (1.0 - albedo))
    }

    /// The von Neumann bound for homogeneous β: the checkerboard mode's amplification
    /// 1 − r(1 − α)/(3β) − 12βr ≥ −1, i.e. r ≤ 6β / (36β² + (1 − α)).
    pub fn von_neumann(beta: f64, albedo: f64) -> f64 {
        6.0 * beta / (36.0 * beta * beta + (1.0 - albedo))
    }

    /// Positivity (the centre weight ≥ 0): r ≤ 6β / (36β² + 2(1 − α)). At this step FTCS
    /// is exactly the Jacobi iteration of the steady equation.
    pub fn positivity(beta: f64, albedo: f64) -> f64 {
        6.0 * beta / (36.0 * beta * beta + 2.0 * (1.0 - albedo))
    }

    /// The same von Neumann bound in physical units, for the largest D (length) and σ_a
    /// (1/length) of a grid of spacing h: cΔt ≤ 2 / (σ_a + 12 D/h²).
    pub fn time_step(d_max: f64, sigma_a_max: f64, h: f64) -> f64 {
        2.0 / (sigma_a_max + 12.0 * d_max / (h * h))
    }
}

/// First-order upwind convection–absorption (Zhang & Ma, Eq. 16): Courant number
/// C = cΔt/Δx, direction u, per-step absorption σ_a ∈ [0, 1].
pub mod upwind {
    use super::DVec3;

    /// The paper's condition, C ≤ 1: the one-dimensional (axis-aligned) bound only.
    pub const PAPER: f64 = 1.0;

    /// The correct bound in 3D: C·(|u| + |v| + |w|) ≤ 1 (monotone and von Neumann stable;
    /// C ≤ 1/√3 for every direction).
    pub fn courant_limit(direction: DVec3) -> f64 {
        let s = direction.abs().element_sum();
        if s > 0.0 { 1.0 / s } else { f64::INFINITY }
    }

    /// The amplification of the checkerboard mode, the first to grow:
    /// (1 − σ_a)·|1 − 2C(|u| + |v| + |w|)| (Zhang & Ma T4).
    pub fn checkerboard_growth(courant: f64, direction: DVec3, sigma_a: f64) -> f64 {
        (1.0 - sigma_a) * (1.0 - 2.0 * courant * direction.abs().element_sum()).abs()
    }

    /// The largest Courant number with no growth at all, absorption included:
    /// (1 − σ_a)(2CS − 1) ≤ 1, i.e. C ≤ (1 + 1/(1 − σ_a)) / (2S).
    pub fn von_neumann_limit(direction: DVec3, sigma_a: f64) -> f64 {
        let s = direction.abs().element_sum();
        if sigma_a >= 1.0 || s == 0.0 {
            return f64::INFINITY;
        }
        (1.0 + 1.0 / (1.0 - sigma_a)) / (2.0 * s)
    }
}

/// Murray's P1 moment system with FTCS: r = cΔt/Δ, damping per step K_φ = cΔt·σ_a on
/// the fluence and K_E = cΔt·σ_t′ on the flux.
pub mod p1 {
    /// The thesis's condition (S5): K < 1 and r/2 < 1. Not sufficient.
    pub fn murray_condition(k: f64, r: f64) -> bool {
        k < 1.0 && r / 2.0 < 1.0
    }

    /// Collocated grid, central differences: the mode matrix has
    /// |G|² = (1 − K_φ)(1 − K_E) + r²(Σ sin²θ)/3, so stability needs
    /// (1 − K_φ)(1 − K_E) + r² ≤ 1; with equal damping (1 − K)² + r² ≤ 1. Returns the
    /// largest r.
    pub fn collocated_limit(k_phi: f64, k_flux: f64) -> f64 {
        (1.0 - (1.0 - k_phi) * (1.0 - k_flux)).max(0.0).sqrt()
    }

    /// Staggered grid (φ at centres, E on faces), both updated from the old values: the
    /// one-cell differences reach 2 sin(θ/2), so (1 − K_φ)(1 − K_E) + 4r² ≤ 1.
    pub fn staggered_limit(k_phi: f64, k_flux: f64) -> f64 {
        0.5 * collocated_limit(k_phi, k_flux)
    }

    /// The largest stable step cΔt (length) on cells of width `h` for absorption σ_a and
    /// reduced extinction σ_t′: r(cΔt) = cΔt/h must not exceed the layout's limit at the
    /// damping cΔt gives; bisected (the limit falls as cΔt grows). 0 without absorption
    /// (no step is stable: the fluence's mode is undamped).
    pub fn largest_step(staggered: bool, sigma_a: f64, sigma_t_reduced: f64, h: f64) -> f64 {
        let limit = |dt: f64| {
            let (k_phi, k_flux) = (dt * sigma_a, dt * sigma_t_reduced);
            if staggered {
                staggered_limit(k_phi, k_flux)
            } else {
                collocated_limit(k_phi, k_flux)
            }
        };
        let (mut lo, mut hi) = (0.0, 2.0 / sigma_t_reduced.max(1e-12));
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if mid / h <= limit(mid) {
                lo = mid
            } else {
                hi = mid
            }
        }
        lo
    }
}

/// FTCS with upwind differences on the unsteady RTE over discrete directions (Murray
/// §3.4.1): r = cΔt/Δ, K = cΔt·σ_t, S = max over the directions of |ω_x| + |ω_y| + |ω_z|.
pub mod ordinates {
    /// Von Neumann (checkerboard mode, isotropic scattering with albedo ≤ 1 adds no
    /// growth): |1 − K − 2rS| ≤ 1, i.e. r ≤ (1 − K/2)/S.
    pub fn von_neumann_limit(s_max: f64, k: f64) -> f64 {
        (1.0 - 0.5 * k) / s_max
    }

    /// Positivity (all weights ≥ 0): r·S + K ≤ 1.
    pub fn positivity_limit(s_max: f64, k: f64) -> f64 {
        (1.0 - k) / s_max
    }

    /// The largest stable step cΔt (length) by [`von_neumann_limit`] on cells of width
    /// `h` with extinction up to `sigma_t_max`: r ≤ (1 − K/2)/S with K = cΔt σ_t gives
    /// cΔt ≤ h/(S + h σ_t/2).
    pub fn largest_step(s_max: f64, sigma_t_max: f64, h: f64) -> f64 {
        h / (s_max + 0.5 * h * sigma_t_max)
    }
}
