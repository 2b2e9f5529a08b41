"""Stability bounds of lucent's explicit schemes, vectorised over numpy arrays.

Each bound comes from von Neumann analysis on a periodic grid (every Fourier mode's
amplification at most 1) or from positivity (all stencil weights ≥ 0); several printed
bounds in the papers are wrong, and these are the corrected ones (``docs/stability.md``
charts them against the blow-ups ``cargo xtask stability`` measures). Arguments broadcast
like numpy's ufuncs; scalars give floats.
"""

from ._broadcast import evaluate


class ftcs_diffusion:
    """Murray's FTCS diffusion (thesis Eq. 4.8, g = 0) in his parameters: β = D/Δ ∈ (0, 1],
    albedo α ∈ [0, 1], step ratio r = cΔt/Δ."""

    @staticmethod
    def murray(beta, albedo):
        """The thesis's bound, Eq. 4.9: r ≤ 6β / (72β² + 9β + 2(1 − α)). Safe, conservative
        by 2.2–3×."""
        return evaluate("ftcs_diffusion.murray", {"beta": beta, "albedo": albedo})

    @staticmethod
    def von_neumann(beta, albedo):
        """The von Neumann bound for homogeneous β: r ≤ 6β / (36β² + (1 − α))."""
        return evaluate("ftcs_diffusion.von_neumann", {"beta": beta, "albedo": albedo})

    @staticmethod
    def positivity(beta, albedo):
        """Positivity (centre weight ≥ 0): r ≤ 6β / (36β² + 2(1 − α))."""
        return evaluate("ftcs_diffusion.positivity", {"beta": beta, "albedo": albedo})

    @staticmethod
    def time_step(d_max, sigma_a_max, h):
        """The von Neumann bound in physical units: cΔt ≤ 2 / (σ_a + 12 D/h²) (length)."""
        return evaluate(
            "ftcs_diffusion.time_step",
            {"d_max": d_max, "sigma_a_max": sigma_a_max, "h": h},
        )


class upwind:
    """First-order upwind convection–absorption (Zhang & Ma, Eq. 16): Courant number
    C = cΔt/Δx, propagation direction u (last axis of length 3), per-step absorption σ_a."""

    #: The paper's condition, C ≤ 1: the one-dimensional bound only.
    PAPER = 1.0

    @staticmethod
    def courant_limit(direction):
        """The correct 3D bound: C ≤ 1 / (|u| + |v| + |w|)."""
        u = _direction(direction)
        return evaluate("upwind.courant_limit", {"ux": u[0], "uy": u[1], "uz": u[2]})

    @staticmethod
    def checkerboard_growth(courant, direction, sigma_a):
        """The checkerboard mode's amplification (1 − σ_a)·|1 − 2C(|u| + |v| + |w|)|."""
        u = _direction(direction)
        return evaluate(
            "upwind.checkerboard_growth",
            {"courant": courant, "ux": u[0], "uy": u[1], "uz": u[2], "sigma_a": sigma_a},
        )

    @staticmethod
    def von_neumann_limit(direction, sigma_a):
        """The largest C with no growth, absorption included: (1 + 1/(1 − σ_a)) / (2S)."""
        u = _direction(direction)
        return evaluate(
            "upwind.von_neumann_limit",
            {"ux": u[0], "uy": u[1], "uz": u[2], "sigma_a": sigma_a},
        )


class p1:
    """Murray's P1 moment system with FTCS: r = cΔt/Δ, damping per step K_φ = cΔt σ_a on
    the fluence and K_E = cΔt σ_t′ on the flux."""

    @staticmethod
    def murray_condition(k, r):
        """The thesis's condition K < 1 and r/2 < 1 (1.0 where it holds). Not sufficient."""
        return evaluate("p1.murray_condition", {"k": k, "r": r})

    @staticmethod
    def collocated_limit(k_phi, k_flux):
        """Largest r on a collocated grid: (1 − K_φ)(1 − K_E) + r² ≤ 1."""
        return evaluate("p1.collocated_limit", {"k_phi": k_phi, "k_flux": k_flux})

    @staticmethod
    def staggered_limit(k_phi, k_flux):
        """Largest r on a staggered grid: (1 − K_φ)(1 − K_E) + 4r² ≤ 1."""
        return evaluate("p1.staggered_limit", {"k_phi": k_phi, "k_flux": k_flux})

    @staticmethod
    def largest_step(staggered, sigma_a, sigma_t_reduced, h):
        """The largest stable cΔt (length) on cells of width h (0 without absorption)."""
        return evaluate(
            "p1.largest_step",
            {
                "staggered": staggered,
                "sigma_a": sigma_a,
                "sigma_t_reduced": sigma_t_reduced,
                "h": h,
            },
        )


class ordinates:
    """FTCS with upwind differences on the unsteady RTE over discrete directions (Murray
    §3.4.1): r = cΔt/Δ, K = cΔt σ_t, S = max over directions of |ω_x| + |ω_y| + |ω_z|."""

    @staticmethod
    def von_neumann_limit(s_max, k):
        """r ≤ (1 − K/2)/S."""
        return evaluate("ordinates.von_neumann_limit", {"s_max": s_max, "k": k})

    @staticmethod
    def positivity_limit(s_max, k):
        """r·S + K ≤ 1."""
        return evaluate("ordinates.positivity_limit", {"s_max": s_max, "k": k})

    @staticmethod
    def largest_step(s_max, sigma_t_max, h):
        """The largest stable cΔt (length): h / (S + h σ_t/2)."""
        return evaluate(
            "ordinates.largest_step", {"s_max": s_max, "sigma_t_max": sigma_t_max, "h": h}
        )


def _direction(direction):
    import numpy as np

    u = np.asarray(direction, dtype=np.float64)
    if u.shape[-1:] != (3,):
        from ._errors import InvalidInputError

        raise InvalidInputError(
            f"`direction`: shape {u.shape}; the last axis must hold (x, y, z)"
        )
    return u[..., 0], u[..., 1], u[..., 2]


__all__ = ["ftcs_diffusion", "upwind", "p1", "ordinates"]
