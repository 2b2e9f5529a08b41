"""Stability bounds and analytic references, vectorised: each against its formula written
out independently in numpy, and the references against each other (energy balance, the
dipole's profile integrating to its total)."""

import numpy as np
import pytest

import lucent
from lucent import analytic, stability


def test_ftcs_bounds_match_their_formulas_and_broadcast():
    beta = np.linspace(0.05, 1.0, 7)[:, None]
    albedo = np.array([0.0, 0.5, 0.99])[None, :]
    vn = stability.ftcs_diffusion.von_neumann(beta, albedo)
    assert vn.shape == (7, 3)
    np.testing.assert_allclose(vn, 6 * beta / (36 * beta**2 + (1 - albedo)), rtol=1e-15)
    murray = stability.ftcs_diffusion.murray(beta, albedo)
    np.testing.assert_allclose(
        murray, 6 * beta / (72 * beta**2 + 9 * beta + 2 * (1 - albedo)), rtol=1e-15
    )
    # The thesis's bound is safe: below von Neumann's everywhere.
    assert (murray < vn).all()
    positivity = stability.ftcs_diffusion.positivity(beta, albedo)
    assert (positivity <= vn).all()
    assert isinstance(stability.ftcs_diffusion.von_neumann(0.5, 0.9), float)


def test_upwind_and_p1_and_ordinates_bounds():
    directions = np.array([[1, 0, 0], [0.6, 0.8, 0], [1, 1, 1] / np.sqrt(3)])
    limits = stability.upwind.courant_limit(directions)
    np.testing.assert_allclose(limits, 1 / np.abs(directions).sum(axis=1), rtol=1e-15)
    assert limits[-1] == pytest.approx(1 / np.sqrt(3))
    growth = stability.upwind.checkerboard_growth(limits, directions, 0.0)
    np.testing.assert_allclose(growth, 1.0, rtol=1e-12)  # exactly neutral at the limit
    k = np.linspace(0, 0.9, 5)
    np.testing.assert_allclose(
        stability.p1.staggered_limit(k, k), 0.5 * np.sqrt(1 - (1 - k) ** 2), rtol=1e-15
    )
    assert stability.p1.murray_condition(0.5, 1.0) == 1.0
    assert stability.p1.murray_condition(0.5, 2.5) == 0.0
    np.testing.assert_allclose(
        stability.ordinates.largest_step(1.5, np.array([0.0, 10.0]), 0.1),
        0.1 / (1.5 + 0.05 * np.array([0.0, 10.0])),
        rtol=1e-15,
    )
    # The P1 step limit at the largest step is the layout's limit (bisection to 1e-12).
    dt = stability.p1.largest_step(True, 0.1, 10.0, 0.05)
    assert dt / 0.05 == pytest.approx(float(stability.p1.staggered_limit(dt * 0.1, dt * 10.0)), rel=1e-9)


def test_half_space_and_sphere_references():
    sigma_a, sigma_s = 0.01, 1.0
    d = 1 / (3 * (sigma_a + sigma_s))
    sigma = np.sqrt(sigma_a / d)
    A = analytic.boundary_factor(1.3)
    assert A == pytest.approx(2.2119, abs=1e-4)
    z = np.linspace(0, 20, 41)
    zp = 2.0
    zb = 2 * A * d
    expected = (
        np.exp(-sigma * np.abs(z - zp))
        - (1 - zb * sigma) / (1 + zb * sigma) * np.exp(-sigma * (z + zp))
    ) / (2 * d * sigma)
    np.testing.assert_allclose(analytic.half_space_fluence(z, zp, sigma_a, sigma_s, A), expected, rtol=1e-13)
    # The sphere: escaped + absorbed = 1 over a range of sizes and absorptions.
    radius = np.array([1.0, 5.0, 20.0])[:, None]
    absorption = np.array([0.001, 0.05, 0.5])[None, :]
    total = analytic.sphere_escaped_fraction(radius, absorption, sigma_s, A) + analytic.sphere_absorbed_fraction(
        radius, absorption, sigma_s, A
    )
    np.testing.assert_allclose(total, 1.0, atol=1e-10)


def test_dipole_profile_integrates_to_its_total():
    """∫ 2πr R_d(r) dr over r = 0..∞ is the dipole's total diffuse reflectance."""
    sigma_a, sigma_s, A = 0.0032, 2.19, analytic.boundary_factor(1.3, "partial-current")
    r = np.geomspace(1e-6, 200.0, 200_001)
    profile = analytic.dipole_reflectance(r, sigma_a, sigma_s, A)
    integral = np.trapezoid(2 * np.pi * r * profile, r) if hasattr(np, "trapezoid") else np.trapz(2 * np.pi * r * profile, r)
    total = analytic.dipole_total_reflectance(sigma_a, sigma_s, A)
    assert integral == pytest.approx(total, rel=2e-3)


def test_bad_arguments_name_the_element():
    with pytest.raises(ValueError, match="sphere.fluence at element 2"):
        analytic.sphere_fluence([0.5, 1.0, 2.0], 1.0, 0.1, 1.0)  # r beyond R
    with pytest.raises(ValueError, match="`r`: NaN at element 1"):
        analytic.dipole_reflectance([0.1, np.nan], 0.1, 1.0)
    with pytest.raises(ValueError, match="do not broadcast"):
        stability.ftcs_diffusion.murray(np.ones(3), np.ones(4))
    with pytest.raises(ValueError, match="last axis"):
        stability.upwind.courant_limit([1.0, 0.0])
    with pytest.raises(ValueError, match="`model`"):
        analytic.boundary_factor(1.3, "fresnel")
