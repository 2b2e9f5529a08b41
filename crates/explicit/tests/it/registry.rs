//! The registry entries on `lucent_core::Problem`s, against the solvers they must agree with.

use glam::DVec3;
use lucent_core::{
    Boundary, DirectSolver, Field, Light, Medium, Params, Problem, SolveOptions, Solver, Spectrum,
};
use lucent_diffusion::DiffusionSolver;
use lucent_explicit::ExplicitSolver;
use lucent_grid::{Grid, GridGeometry};
use lucent_optics::Phase;

fn problem(n: usize, sigma_t: f32, albedo: f64, lights: Vec<Light>, boundary: Boundary) -> Problem {
    let geometry = GridGeometry::from_bounds([n; 3], DVec3::ZERO, DVec3::splat(n as f64)).unwrap();
    let medium = Medium {
        sigma_t: vec![Grid::filled(geometry, sigma_t)],
        albedo: vec![Field::Constant(albedo as f32)],
        phase: Phase::Isotropic,
    };
    Problem::new(geometry, medium, lights, boundary, None).unwrap()
}

fn relative_l2(a: &Grid, b: &Grid) -> f64 {
    let (mut d, mut s) = (0.0, 0.0);
    for (x, y) in a.data().iter().zip(b.data()) {
        d += (f64::from(*x) - f64::from(*y)).powi(2);
        s += f64::from(*y).powi(2);
    }
    (d / s).sqrt()
}

#[test]
fn ftcs_and_jacobi_diffusion_equal_diffusion_mg_through_the_registry() {
    // Same discrete problem (a point light in a 12³ scattering box, Robin η = 1.3): to
    // 1e-10 each, they agree to 1e-5 (f32 output rounding is 6e-8).
    let p = problem(
        12,
        1.0,
        0.95,
        vec![Light::Point {
            position: DVec3::new(6.2, 5.9, 6.1),
            intensity: Spectrum::Grey(1.0),
        }],
        Boundary::Robin { eta: 1.3 },
    );
    let options = SolveOptions {
        relative_tolerance: 1e-10,
        max_iterations: 1_000_000,
        ..SolveOptions::default()
    };
    let mg = (DiffusionSolver::MULTIGRID.build)(&Params::default())
        .unwrap()
        .solve(&p, &options)
        .unwrap();
    for entry in [
        ExplicitSolver::FTCS_DIFFUSION,
        ExplicitSolver::JACOBI_DIFFUSION,
    ] {
        let s = (entry.build)(&Params::default())
            .unwrap()
            .solve(&p, &options)
            .unwrap();
        assert!(
            s.report.stop_reason.is_converged(),
            "{}: {:?}",
            entry.name,
            s.report.stop_reason
        );
        let e = relative_l2(s.fluence(0), mg.fluence(0));
        assert!(e < 1e-5, "{}: {e}", entry.name);
    }
}

#[test]
fn convection_without_scattering_matches_direct() {
    // Zhang & Ma's conservative upwind on an oblique sun through a homogeneous 24³ block
    // (σ_t h = 0.1): the uncollided fluence, against `direct`'s exact line integrals. First
    // order: 7.3% relative L2 measured here, from the per-cell attenuation (the fixed
    // point 1/(1 + σh/|u_z|)-like factor against e^{−σh/|u_z|}) accumulated along the path,
    // and the beam's smearing across the oblique cells.
    let p = problem(
        24,
        0.1,
        0.0,
        vec![Light::Directional {
            direction: DVec3::new(0.3, 0.2, 1.0).normalize(),
            irradiance: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
    );
    let direct = DirectSolver::default()
        .solve(&p, &SolveOptions::default())
        .unwrap();
    let upwind = (ExplicitSolver::CONVECTION_DIFFUSION.build)(&Params::default())
        .unwrap()
        .solve(&p, &SolveOptions::default())
        .unwrap();
    let e = relative_l2(upwind.fluence(0), direct.fluence(0));
    assert!(e < 0.1, "{e}");
}

#[test]
fn staggered_p1_and_ordinates_approach_diffusion_in_a_thick_medium() {
    // A point light in a thick scattering medium (σ_t h = 1, albedo 0.9, 15³): P1's steady
    // state is diffusion, and S4 ordinates are close to it a few mean free paths out.
    // Compared on the cells 2–4 cells from the light. diffusion-mg takes the source's
    // singular part analytically and is the continuum diffusion solution there (within
    // 0.5% of the infinite-medium Green's function at 1–2 cells); P1 by FTCS puts the power
    // into the light's cell, whose discretisation error at one mean free path per cell
    // makes it 17.8% high at 2 cells, 11% at 4 (when diffusion-mg had the same cell source
    // they agreed to 1.2%): within 20%.
    let p = problem(
        15,
        1.0,
        0.9,
        vec![Light::Point {
            position: DVec3::splat(7.5),
            intensity: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
    );
    let options = SolveOptions {
        relative_tolerance: 1e-8,
        max_iterations: 200_000,
        ..SolveOptions::default()
    };
    let mg = (DiffusionSolver::MULTIGRID.build)(&Params::default())
        .unwrap()
        .solve(&p, &options)
        .unwrap();
    let (lo, hi) = (2.0, 4.0);
    let g = *p.geometry();
    let shell: Vec<usize> = (0..g.voxel_count())
        .filter(|&c| {
            let [i, j, k] = g.coords(c);
            let r = (g.cell_centre(i, j, k) - DVec3::splat(7.5)).length();
            (lo..=hi).contains(&r)
        })
        .collect();
    let compare = |s: &lucent_core::Solution| {
        shell
            .iter()
            .map(|&c| {
                (f64::from(s.fluence(0).data()[c]) / f64::from(mg.fluence(0).data()[c]) - 1.0).abs()
            })
            .fold(0.0, f64::max)
    };
    let p1 = (ExplicitSolver::FTCS_P1.build)(&Params::default())
        .unwrap()
        .solve(&p, &options)
        .unwrap();
    assert!(
        p1.report.stop_reason.is_converged(),
        "{:?}",
        p1.report.stop_reason
    );
    assert!(compare(&p1) < 0.20, "P1: {}", compare(&p1));
    let ord = (ExplicitSolver::FTCS_ORDINATES.build)(&Params::default())
        .unwrap()
        .solve(&p, &options)
        .unwrap();
    assert!(
        ord.report.stop_reason.is_converged(),
        "{:?}",
        ord.report.stop_reason
    );
    // S4 differs from diffusion cell by cell by up to 35%, and its shell mean is 21% lower
    // (measured): transport near a source, its rays, first-order upwind in cells a mean
    // free path wide. What it must get exactly is energy: see the next test.
}

#[test]
fn ordinates_and_p1_conserve_energy() {
    // An absorbing medium (σ_t h = 1, albedo 0.5) so thick that almost nothing reaches the
    // 15³ box's faces (uncollided e^{−7} ≈ 1e-3 at most): absorbed power ∫σ_a φ dV equals
    // the emitted 4πI to 1%.
    let p = problem(
        15,
        1.0,
        0.5,
        vec![Light::Point {
            position: DVec3::splat(7.5),
            intensity: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
    );
    let options = SolveOptions {
        relative_tolerance: 1e-9,
        max_iterations: 200_000,
        ..SolveOptions::default()
    };
    let emitted = 4.0 * std::f64::consts::PI;
    for entry in [ExplicitSolver::FTCS_ORDINATES, ExplicitSolver::FTCS_P1] {
        let s = (entry.build)(&Params::default())
            .unwrap()
            .solve(&p, &options)
            .unwrap();
        let absorbed: f64 = s
            .fluence(0)
            .data()
            .iter()
            .map(|&v| 0.5 * f64::from(v))
            .sum();
        assert!(
            (absorbed / emitted - 1.0).abs() < 0.01,
            "{}: {absorbed} vs {emitted}",
            entry.name
        );
    }
}

/// Relative L2 error of `convection-diffusion` with `model` against `direct` (exact at cell
/// centres) under an oblique sun on a purely absorbing medium: `layered` is
/// σ_t = 2 + 1.5 sin(2π z/1.5), which fills the box [0, 1]² × [0, 1.5] (n × n × 3n/2 cells),
/// so the light enters through the top and two sides and the field has kinks along the
/// planes through the box's top edges; otherwise a Gaussian blob (peak 8, width 0.15) that
/// vanishes at the faces, for a smooth field.
fn oblique_sun_error(model: &str, n: usize, layered: bool) -> f64 {
    use lucent_core::{Field, Medium, ParamValue, Problem};
    use lucent_grid::{Grid, GridGeometry};
    let geometry =
        GridGeometry::from_bounds([n, n, 3 * n / 2], DVec3::ZERO, DVec3::new(1.0, 1.0, 1.5))
            .unwrap();
    let sigma_t = Grid::from_fn(geometry, |x| {
        if layered {
            (2.0 + 1.5 * (2.0 * std::f64::consts::PI * x.z / 1.5).sin()) as f32
        } else {
            let r2 = (x - DVec3::new(0.5, 0.5, 0.75)).length_squared();
            (8.0 * (-r2 / (2.0 * 0.15f64.powi(2))).exp()) as f32
        }
    });
    let medium = Medium {
        sigma_t: vec![sigma_t],
        albedo: vec![Field::Constant(0.0)],
        phase: lucent_optics::Phase::Isotropic,
    };
    let sun = Light::Directional {
        direction: DVec3::new(-0.3, -0.4, -0.8).normalize(),
        irradiance: Spectrum::Grey(1.0),
    };
    let p = Problem::new(geometry, medium, vec![sun], Boundary::Vacuum, None).unwrap();
    let direct = DirectSolver::default()
        .solve(&p, &SolveOptions::default())
        .unwrap();
    let mut params = Params::default();
    params
        .0
        .insert("model".into(), ParamValue::Text(model.into()));
    if model != "characteristic" {
        // The upwind bound for this sun: C (|u| + |v| + |w|) ≤ 1.
        params.0.insert("courant".into(), ParamValue::Float(0.4));
    }
    let upwind = (ExplicitSolver::CONVECTION_DIFFUSION.build)(&params)
        .unwrap()
        .solve(&p, &SolveOptions::default())
        .unwrap();
    relative_l2(upwind.fluence(0), direct.fluence(0))
}

#[test]
fn short_characteristics_beat_upwinding_in_error_and_order() {
    // Against `direct` (exact), relative L2 at 16×16×24 → 32×32×48 (→ 64×64×96 measured
    // once, not run here):
    // - smooth blob: characteristic 7.2e-3 → 2.1e-3 (→ 5.6e-4), order 1.7–1.9 (monotone
    //   biquadratic interpolation, exact attenuation); conservative upwind 5.9e-2 → 3.4e-2
    //   (→ 1.9e-2) and the paper's Eq. 16 5.6e-2 → 3.3e-2 (→ 1.8e-2), order 0.8;
    // - layered box, kinks where the light enters through its edges: characteristic
    //   2.1e-2 → 1.1e-2 (→ 5.6e-3), order 0.95; upwind 6.8e-2 → 4.5e-2 (→ 2.8e-2), 0.6.
    let errors = |model: &str, layered: bool| {
        let (coarse, fine) = (
            oblique_sun_error(model, 16, layered),
            oblique_sun_error(model, 32, layered),
        );
        eprintln!(
            "{model} (layered {layered}): {coarse:.3e} → {fine:.3e}, order {:.2}",
            (coarse / fine).log2()
        );
        (fine, (coarse / fine).log2())
    };
    let (smooth, order) = errors("characteristic", false);
    assert!(
        order > 1.6 && smooth < 3e-3,
        "characteristic: {smooth}, {order}"
    );
    let (kinked, order) = errors("characteristic", true);
    assert!(
        order > 0.8 && kinked < 1.5e-2,
        "characteristic: {kinked}, {order}"
    );
    for model in ["conservative", "paper"] {
        let (e, order) = errors(model, false);
        assert!(order < 1.1 && e > 10.0 * smooth, "{model}: {e}, {order}");
        let (e, _) = errors(model, true);
        assert!(e > 3.0 * kinked, "{model}: {e}");
    }
}

#[test]
fn a_step_beyond_the_stability_bound_is_refused_with_the_numbers() {
    // Through the registry a refused step is a typed `SolveError::Unstable` that carries
    // the bound and the request (nothing runs); `allow_unstable` runs it and the growth
    // monitor stops it.
    use lucent_core::{ParamValue, SolveError};
    let p = problem(
        12,
        1.0,
        0.5,
        vec![Light::Directional {
            direction: DVec3::new(1.0, 1.0, 1.0).normalize(),
            irradiance: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
    );
    let mut params = Params::default();
    params
        .0
        .insert("model".into(), ParamValue::Text("conservative".into()));
    params.0.insert("courant".into(), ParamValue::Float(0.9));
    let err = (ExplicitSolver::CONVECTION_DIFFUSION.build)(&params)
        .unwrap()
        .solve(&p, &SolveOptions::default())
        .unwrap_err();
    match err {
        SolveError::Unstable {
            limit, requested, ..
        } => {
            // C (|u| + |v| + |w| + σh) ≤ 1 with |u| + |v| + |w| = √3 and σh = 1.
            assert!((limit - 1.0 / (3f64.sqrt() + 1.0)).abs() < 1e-9, "{limit}");
            assert_eq!(requested, 0.9);
        }
        other => panic!("{other}"),
    }
    let mut params = Params::default();
    params
        .0
        .insert("step_fraction".into(), ParamValue::Float(1.5));
    let err = (ExplicitSolver::FTCS_DIFFUSION.build)(&params)
        .unwrap()
        .solve(&p, &SolveOptions::default())
        .unwrap_err();
    assert!(
        matches!(err, SolveError::Unstable { limit, requested, .. } if limit == 1.0 && requested == 1.5),
        "{err}"
    );
}

#[test]
fn the_default_courant_number_is_stable_for_every_light_and_model() {
    // Without `courant`, each upwind march runs at ½ or at its light's bound where that is
    // lower: oblique suns (|u| + |v| + |w| up to √3, bound 0.58 for Paper and lower for
    // Conservative, whose bound also holds h·σ_a) and a point light in the box all run,
    // and the stopping rule sees them converge. Before the default came from the bound,
    // these were refused as unstable at 0.5.
    use lucent_core::{ParamValue, SolveError};
    let suns = [
        DVec3::new(-0.3, -0.4, -0.8),
        DVec3::new(1.0, 1.0, 1.0),
        DVec3::new(0.2, -0.9, 0.1),
    ];
    for model in ["conservative", "paper"] {
        for sigma_t in [0.3f32, 1.0] {
            let mut lights: Vec<Light> = suns
                .iter()
                .map(|d| Light::Directional {
                    direction: d.normalize(),
                    irradiance: Spectrum::Grey(1.0),
                })
                .collect();
            lights.push(Light::Point {
                position: DVec3::new(3.3, 4.1, 5.7),
                intensity: Spectrum::Grey(1.0),
            });
            let p = problem(10, sigma_t, 0.0, lights, Boundary::Vacuum);
            let mut params = Params::default();
            params
                .0
                .insert("model".into(), ParamValue::Text(model.into()));
            let solution = (ExplicitSolver::CONVECTION_DIFFUSION.build)(&params)
                .unwrap()
                .solve(&p, &SolveOptions::default())
                .unwrap_or_else(|e: SolveError| panic!("{model}, σ_t {sigma_t}: {e}"));
            assert!(
                solution.report.stop_reason.is_converged(),
                "{model}, σ_t {sigma_t}: {:?}",
                solution.report.stop_reason
            );
        }
    }
}
