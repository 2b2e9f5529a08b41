"""Closed-form references of diffusion theory (``lucent-optics``), vectorised over numpy
arrays: what lucent's solvers are tested against.

A medium is given by its absorption ``sigma_a`` and reduced scattering ``sigma_s_reduced``
(1/length; D = 1/(3(σ_a + σ_s′)), σ_tr = √(σ_a/D)) and the boundary factor ``A`` of the
Robin condition φ + 2AD ∂φ/∂n = 0 (1 for an index-matched surface;
``boundary_factor(eta)`` for a dielectric one). Every argument broadcasts.
"""

from ._broadcast import evaluate


def beer_lambert(optical_depth):
    """Transmittance e^{−τ} through optical depth τ ≥ 0."""
    return evaluate("beer_lambert", {"optical_depth": optical_depth})


def boundary_factor(eta, model="milne"):
    """The boundary factor A for relative refractive index η: ``milne`` (the
    transport-exact extrapolation length, A = 3z_b/2, what lucent's diffusion solvers
    use; 1.0657 at η = 1), ``groenhuis`` (Groenhuis's fit), ``partial-current``
    (Haskell's; 2.341 at η = 1.3), ``exact`` (the partial-current integrals by
    quadrature)."""
    name = {
        "milne": "boundary_factor.milne",
        "groenhuis": "boundary_factor.groenhuis",
        "partial-current": "boundary_factor.partial_current",
        "exact": "boundary_factor.exact",
    }.get(model)
    if name is None:
        from ._errors import InvalidInputError

        raise InvalidInputError(
            f"`model`: `{model}`: milne, groenhuis, partial-current or exact"
        )
    return evaluate(name, {"eta": eta})


def infinite_medium_fluence(r, sigma_a, sigma_s_reduced, power=1.0):
    """The infinite medium's Green's function P e^{−σ_tr r}/(4π D r) at r > 0."""
    return evaluate(
        "infinite_medium_fluence",
        {"sigma_a": sigma_a, "sigma_s_reduced": sigma_s_reduced, "power": power, "r": r},
    )


def dipole_reflectance(r, sigma_a, sigma_s_reduced, A=1.0):
    """The classical dipole's diffuse reflectance profile R_d(r) (1/length²) at distance
    r ≥ 0 from the point of incidence (Jensen et al. 2001)."""
    return evaluate(
        "dipole.reflectance_profile",
        {"sigma_a": sigma_a, "sigma_s_reduced": sigma_s_reduced, "A": A, "r": r},
    )


def dipole_total_reflectance(sigma_a, sigma_s_reduced, A=1.0):
    """The dipole's total diffuse reflectance ∫ R_d dA (Jensen et al. 2001, Eq. 6 integrated)."""
    return evaluate(
        "dipole.total_reflectance",
        {"sigma_a": sigma_a, "sigma_s_reduced": sigma_s_reduced, "A": A},
    )


def sphere_fluence(r, radius, sigma_a, sigma_s_reduced, A=1.0):
    """Fluence at 0 < r ≤ R in a sphere of radius R with a unit point source at its centre
    and a Robin surface (Mertens T7). Needs σ_a > 0."""
    return evaluate(
        "sphere.fluence",
        {
            "sigma_a": sigma_a,
            "sigma_s_reduced": sigma_s_reduced,
            "A": A,
            "radius": radius,
            "r": r,
        },
    )


def sphere_escaped_fraction(radius, sigma_a, sigma_s_reduced, A=1.0):
    """Fraction of the central source's power leaving the sphere, 4πR² φ(R)/(2A)."""
    return evaluate(
        "sphere.escaped_fraction",
        {"sigma_a": sigma_a, "sigma_s_reduced": sigma_s_reduced, "A": A, "radius": radius},
    )


def sphere_absorbed_fraction(radius, sigma_a, sigma_s_reduced, A=1.0):
    """Fraction absorbed inside the sphere, ∫ σ_a φ dV (escaped + absorbed = 1)."""
    return evaluate(
        "sphere.absorbed_fraction",
        {"sigma_a": sigma_a, "sigma_s_reduced": sigma_s_reduced, "A": A, "radius": radius},
    )


def half_space_fluence(z, source_depth, sigma_a, sigma_s_reduced, A=1.0):
    """Fluence at depth z ≥ 0 in the half-space z ≥ 0 with a unit plane source at depth
    z′ ≥ 0 and a Robin surface at z = 0 (Mertens T9). Needs σ_a > 0."""
    return evaluate(
        "half_space.fluence",
        {
            "sigma_a": sigma_a,
            "sigma_s_reduced": sigma_s_reduced,
            "A": A,
            "source_depth": source_depth,
            "z": z,
        },
    )


def half_space_exitance(source_depth, sigma_a, sigma_s_reduced, A=1.0):
    """The half-space's radiant exitance φ(0)/(2A) = e^{−σ_tr z′}/(1 + 2ADσ_tr)."""
    return evaluate(
        "half_space.exitance",
        {
            "sigma_a": sigma_a,
            "sigma_s_reduced": sigma_s_reduced,
            "A": A,
            "source_depth": source_depth,
        },
    )


__all__ = [
    "beer_lambert",
    "boundary_factor",
    "infinite_medium_fluence",
    "dipole_reflectance",
    "dipole_total_reflectance",
    "sphere_fluence",
    "sphere_escaped_fraction",
    "sphere_absorbed_fraction",
    "half_space_fluence",
    "half_space_exitance",
]
