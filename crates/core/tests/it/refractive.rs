//! `direct-refractive` against `direct` where rays are straight, and against the
//! conservation of flux where they bend.

use glam::DVec3;
use lucent_core::{
    Boundary, DirectRefractiveSolver, DirectSolver, Field, IndexGrid, Light, Medium, Problem,
    RefractiveIndex, SolveError, SolveOptions, Solver, Spectrum,
};
use lucent_grid::{Grid, GridGeometry};
use lucent_optics::Phase;
use lucent_optics::eikonal::{GaussianBump, LinearIndex, Luneburg};

/// A heterogeneous medium (a smooth blob over a floor) with the given grid.
fn blob(geometry: GridGeometry) -> Medium {
    let (lo, hi) = geometry.bounds();
    let centre = 0.5 * (lo + hi);
    let size = (hi - lo).length();
    Medium {
        sigma_t: vec![Grid::from_fn(geometry, |p| {
            (0.3 + 4.0 * (-((p - centre).length_squared()) / (0.1 * size * size)).exp()) as f32
        })],
        albedo: vec![Field::Constant(0.7)],
        phase: Phase::henyey_greenstein(0.4).unwrap(),
    }
}

fn lights(geometry: GridGeometry) -> Vec<Light> {
    let (lo, hi) = geometry.bounds();
    let centre = 0.5 * (lo + hi);
    vec![
        Light::Directional {
            direction: DVec3::new(0.3, -0.5, 0.8).normalize(),
            irradiance: Spectrum::Grey(2.0),
        },
        // Inside the box, off the cell centres.
        Light::Point {
            position: lo + (hi - lo) * DVec3::new(0.23, 0.61, 0.37),
            intensity: Spectrum::Grey(0.5),
        },
        // Outside the box.
        Light::Spot {
            position: centre + DVec3::new(-1.3, 0.2, 0.9) * (hi - lo).length(),
            direction: (centre - (centre + DVec3::new(-1.3, 0.2, 0.9) * (hi - lo).length()))
                .normalize(),
            intensity: Spectrum::Grey(3.0),
            inner_angle: 0.05,
            outer_angle: 0.3,
        },
        Light::Sky {
            radiance: Spectrum::Grey(0.25),
        },
    ]
}

/// With a uniform index every ray is straight: `direct-refractive` gives `direct`'s fluence
/// and in-scattered radiance to rounding, on boxes of several shapes, with and without an
/// index (η = 1.33 changes nothing: the box is index-matched). The tolerance, 2e-5
/// relative: both store f32 (6e-8), and the curved solver's optical depth is a sum of
/// chord integrals where `direct` takes one (τ ≲ 3 here, so e^{−τ} moves by its rounding
/// times τ); the sky's directions are gathered backwards rather than forwards.
#[test]
fn a_uniform_index_gives_direct_to_rounding() {
    for (dims, spacing, index) in [
        ([9, 7, 11], DVec3::splat(0.1), None),
        (
            [13, 6, 5],
            DVec3::new(0.05, 0.08, 0.11),
            Some(RefractiveIndex::Uniform(1.33)),
        ),
        (
            [6, 10, 7],
            DVec3::splat(0.2),
            Some(RefractiveIndex::Grid(IndexGrid::new(Grid::filled(
                GridGeometry::new([6, 10, 7], DVec3::splat(0.2), DVec3::ZERO).unwrap(),
                1.5,
            )))),
        ),
    ] {
        let geometry = GridGeometry::new(dims, spacing, DVec3::ZERO).unwrap();
        let mut problem = Problem::new(
            geometry,
            blob(geometry),
            lights(geometry),
            Boundary::Vacuum,
            None,
        )
        .unwrap();
        if let Some(index) = index {
            problem = problem.with_refractive_index(index).unwrap();
        }
        let options = SolveOptions::default();
        let straight = DirectSolver::default().solve(&problem, &options).unwrap();
        let curved = DirectRefractiveSolver::default()
            .solve(&problem, &options)
            .unwrap();
        let (a, b) = (straight.fluence(0).data(), curved.fluence(0).data());
        for (cell, (x, y)) in a.iter().zip(b).enumerate() {
            assert!(
                (x - y).abs() <= 2e-5 * x.abs().max(1e-6),
                "{dims:?}: cell {cell}: direct {x}, curved {y}"
            );
        }
        let (lo, hi) = geometry.bounds();
        for t in [0.2, 0.5, 0.77] {
            let x = lo + (hi - lo) * DVec3::new(t, 1.0 - t, 0.5 * t + 0.2);
            let omega = DVec3::new(0.2, 0.9, -0.3).normalize();
            let (s, c) = (
                straight.inscattered(0, x, omega),
                curved.inscattered(0, x, omega),
            );
            assert!(
                (s - c).abs() <= 1e-4 * s.abs(),
                "in-scattered at {x}: {s} vs {c}"
            );
        }
    }
}

/// The flux of a beam through a refracting, non-absorbing medium is conserved: a
/// directional light along z through a Gaussian bump of index (η = 1 + 0.02 e^{−r²/w²},
/// w = 0.15: a weak converging lens whose focus lies beyond the box) carries, across every
/// cell-centre plane, the flux it brought in, Σ E (t·z) dA = the face's area, to 1e-4
/// (measured: 1.3e-6, the f32 storage). The bump is e^{−11} at the box's sides, so no ray
/// leaves through them, and the integrand is smooth and flat at the plane's edges, where
/// the midpoint rule is spectrally accurate: what is left is the ray tubes' flux
/// accounting. (A grid's B-spline index is not a fair field for this check: its Hessian
/// kinks at the cell-centre planes, which the midpoint rule samples, an aliasing error of
/// ~1e-4.) The irradiance itself varies by tens of percent.
#[test]
fn a_beam_keeps_its_flux_through_a_graded_index() {
    let n = 24;
    let geometry = GridGeometry::new([n, n, n], DVec3::splat(1.0 / n as f64), DVec3::ZERO).unwrap();
    let lens = GaussianBump {
        eta0: 1.0,
        amplitude: 0.02,
        centre: DVec3::new(0.5, 0.5, 0.3),
        width: 0.15,
    };
    let medium = Medium {
        sigma_t: vec![Grid::filled(geometry, 0.0)],
        albedo: vec![Field::Constant(0.0)],
        phase: Phase::Isotropic,
    };
    let problem = Problem::new(
        geometry,
        medium,
        vec![Light::Directional {
            direction: DVec3::Z,
            irradiance: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
        None,
    )
    .unwrap()
    .with_refractive_index(RefractiveIndex::Gaussian(lens))
    .unwrap();
    let solution = DirectRefractiveSolver::default()
        .solve(&problem, &SolveOptions::default())
        .unwrap();
    let Some(lucent_core::Angular::Lights(lights)) = &solution.angular else {
        panic!("direct-refractive keeps its arrivals");
    };
    let arrival = &lights.arrivals[0];
    let (mut lowest, mut highest) = (f64::MAX, 0.0f64);
    for k in 0..n {
        let mut flux = 0.0;
        for j in 0..n {
            for i in 0..n {
                let index = i + n * (j + n * k);
                // A unit beam along z: E = the focusing, t_z = 1 + the bend's z.
                let e = f64::from(arrival.focusing.data()[index]);
                let tz = 1.0 + f64::from(arrival.bend[2].data()[index]);
                lowest = lowest.min(e);
                highest = highest.max(e);
                flux += e * tz / (n * n) as f64;
            }
        }
        assert!((flux - 1.0).abs() < 1e-4, "plane {k}: flux {flux}");
    }
    assert!(
        highest > 1.2 && lowest < 0.99,
        "the lens focuses: E in [{lowest}, {highest}]"
    );
}

/// A Luneburg lens focuses a beam on its far rim: the irradiance just inside the rim on
/// the axis is many times the beam's, and off the axis at the same depth it is not.
#[test]
fn a_luneburg_lens_concentrates_the_beam_on_its_far_rim() {
    let n = 21;
    let geometry = GridGeometry::new([n, n, n], DVec3::splat(1.0 / n as f64), DVec3::ZERO).unwrap();
    let medium = Medium {
        sigma_t: vec![Grid::filled(geometry, 0.0)],
        albedo: vec![Field::Constant(0.0)],
        phase: Phase::Isotropic,
    };
    let radius = 0.4;
    let problem = Problem::new(
        geometry,
        medium,
        vec![Light::Directional {
            direction: DVec3::Z,
            irradiance: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
        None,
    )
    .unwrap()
    .with_refractive_index(RefractiveIndex::Luneburg(Luneburg {
        centre: DVec3::splat(0.5),
        radius,
    }))
    .unwrap();
    let solution = DirectRefractiveSolver::default()
        .solve(&problem, &SolveOptions::default())
        .unwrap();
    let phi = solution.fluence(0);
    // Cell (10, 10, 18): centre z = 0.881, 0.019 inside the rim at z = 0.9.
    let on_axis = f64::from(phi.data()[10 + n * (10 + n * 18)]);
    let off_axis = f64::from(phi.data()[4 + n * (10 + n * 18)]);
    assert!(on_axis > 20.0, "on the axis near the focus: {on_axis}");
    assert!(off_axis < 2.0, "off the axis: {off_axis}");
}

/// Bad input: a non-positive index is the problem's error; a graded index is refused by
/// solvers that trace straight rays; bad parameters are named.
#[test]
fn bad_indices_and_parameters_are_errors() {
    let geometry = GridGeometry::new([4, 4, 4], DVec3::splat(0.25), DVec3::ZERO).unwrap();
    let problem = Problem::new(
        geometry,
        blob(geometry),
        lights(geometry),
        Boundary::Vacuum,
        None,
    )
    .unwrap();
    assert!(
        problem
            .clone()
            .with_refractive_index(RefractiveIndex::Uniform(0.0))
            .is_err()
    );
    // η = 1 − 2x reaches −1 at the far corner.
    let falling = RefractiveIndex::Linear(LinearIndex {
        eta0: 1.0,
        gradient: DVec3::new(-2.0, 0.0, 0.0),
        origin: DVec3::ZERO,
    });
    assert!(problem.clone().with_refractive_index(falling).is_err());
    let graded = problem
        .with_refractive_index(RefractiveIndex::Linear(LinearIndex {
            eta0: 1.2,
            gradient: DVec3::new(0.1, 0.0, 0.0),
            origin: DVec3::ZERO,
        }))
        .unwrap();
    assert!(matches!(
        DirectSolver::default().solve(&graded, &SolveOptions::default()),
        Err(SolveError::Unsupported { .. })
    ));
    for bad in [
        DirectRefractiveSolver {
            tolerance: 0.0,
            ..Default::default()
        },
        DirectRefractiveSolver {
            aim: 1.0,
            ..Default::default()
        },
    ] {
        assert!(matches!(
            bad.solve(&graded, &SolveOptions::default()),
            Err(SolveError::InvalidParameter { .. })
        ));
    }
}
