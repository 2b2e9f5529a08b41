//! Resolution chosen by need (`lucent::resolution`): the Richardson-style estimates
//! against the true discretisation error, measured against a solve on a grid twice as
//! fine, and the choice of the coarsest level that meets a tolerance.

use glam::DVec3;
use lucent::core::{Boundary, Field, Light, Medium, Params, Problem, SolveOptions, Spectrum};
use lucent::grid::resample::resample;
use lucent::grid::{Grid, GridGeometry};
use lucent::optics::Phase;
use lucent::resolution::{AngularFamily, coarsest_meeting, fewest_directions_meeting, on_grid};

/// A marble-like cube (σ_t = 8, albedo 0.98, Robin boundary) lit by an oblique sun: smooth
/// inside, with the boundary layer and first-collision source that set the error.
fn cube(n: usize) -> Problem {
    let geometry = GridGeometry::from_bounds([n, n, n], DVec3::ZERO, DVec3::splat(1.0)).unwrap();
    Problem::new(
        geometry,
        Medium {
            sigma_t: vec![Grid::filled(geometry, 8.0)],
            albedo: vec![Field::Constant(0.98)],
            phase: Phase::Isotropic,
        },
        vec![Light::Directional {
            direction: DVec3::new(0.3, 0.2, -1.0).normalize(),
            irradiance: Spectrum::Grey(1.0),
        }],
        Boundary::Robin { eta: 1.3 },
        None,
    )
    .unwrap()
}

fn relative_l2(a: &Grid, reference: &Grid) -> f64 {
    let (mut diff, mut norm) = (0.0f64, 0.0f64);
    for (x, r) in a.data().iter().zip(reference.data()) {
        diff += (f64::from(*x) - f64::from(*r)).powi(2);
        norm += f64::from(*r).powi(2);
    }
    (diff / norm).sqrt()
}

/// On `diffusion-mg` (second order), 32³ with its 16³ and 8³ levels: the observed order
/// lies between 1.3 and 2.7 (measured 1.4: at 8³ cells of 1/8, about one ℓ′, the
/// boundary layer and the first-collision source are not yet in the asymptotic range),
/// and each level's estimate is within a factor 3 of its true error against the same
/// problem on 64³ (measured 1.1–2.1: a factor 3 is what such an estimate is good for; a
/// wrong order or a level compared on the wrong cells is off by far more). The choice follows
/// the tolerance: a tolerance between two levels' estimates picks the finer of them, one
/// above every estimate the coarsest.
#[test]
fn estimates_track_the_true_error_and_the_choice_follows_the_tolerance() {
    let solver = lucent::registry()
        .build("diffusion-mg", &Params::default())
        .unwrap();
    // Iteration error far below the discretisation's.
    let options = SolveOptions {
        relative_tolerance: 1e-10,
        ..SolveOptions::default()
    };
    let problem = cube(32);
    let choice = coarsest_meeting(&problem, solver.as_ref(), 1e-9, &options).unwrap();
    assert_eq!(choice.levels.len(), 3);
    assert_eq!(
        choice.levels.iter().map(|l| l.dims[0]).collect::<Vec<_>>(),
        [32, 16, 8]
    );
    eprintln!("{choice:#?}");
    assert!(
        choice.observed && (1.3..=2.7).contains(&choice.order),
        "{choice:?}"
    );
    // Nothing meets 1e-9: the finest is chosen, not met, and the refinement it would need
    // is reported.
    assert!(!choice.met && choice.chosen == 0);
    assert!(choice.needed_refinement(1e-9).unwrap() > 1.0);
    // The truth: each level against the 64³ solve box-averaged onto its cells.
    let reference = solver
        .solve(&on_grid(&problem, [64; 3]).unwrap(), &options)
        .unwrap();
    for level in &choice.levels {
        let grid = if level.coarsening == 1 {
            problem.clone()
        } else {
            on_grid(&problem, level.dims).unwrap()
        };
        let solved = solver.solve(&grid, &options).unwrap();
        let truth = relative_l2(
            solved.fluence(0),
            &resample(reference.fluence(0), level.dims).unwrap(),
        );
        let ratio = level.estimated_error / truth;
        eprintln!(
            "{:?}: estimated {:.3e}, true {truth:.3e}",
            level.dims, level.estimated_error
        );
        assert!(
            (1.0 / 3.0..=3.0).contains(&ratio),
            "{level:?}: true {truth:e}"
        );
    }
    // Between the 32³ and 16³ estimates: 32³; above all of them: 8³.
    let between = (choice.levels[0].estimated_error * choice.levels[1].estimated_error).sqrt();
    let picked = coarsest_meeting(&problem, solver.as_ref(), between, &options).unwrap();
    assert!(picked.met && picked.chosen == 0, "{picked:?}");
    let loose = choice.levels[2].estimated_error * 1.01;
    let picked = coarsest_meeting(&problem, solver.as_ref(), loose, &options).unwrap();
    assert!(picked.met && picked.chosen == 2, "{picked:?}");
}

/// What gives no estimate is an error, not a NaN: a grid with no coarser level of
/// `MIN_CELLS` cells across, and a solve stopped by its iteration limit (its differences
/// would measure the iteration, not the grid).
#[test]
fn no_coarser_level_and_unconverged_solves_are_errors() {
    let solver = lucent::registry()
        .build("diffusion-mg", &Params::default())
        .unwrap();
    let tight = SolveOptions {
        relative_tolerance: 1e-10,
        ..SolveOptions::default()
    };
    match coarsest_meeting(&cube(6), solver.as_ref(), 0.1, &tight) {
        Err(lucent::Error::Invalid(reason)) => {
            assert!(reason.contains("no grid 2× coarser"), "{reason}")
        }
        other => panic!("{other:?}"),
    }
    let one_cycle = SolveOptions {
        relative_tolerance: 1e-10,
        max_iterations: 1,
        ..SolveOptions::default()
    };
    match coarsest_meeting(&cube(16), solver.as_ref(), 0.1, &one_cycle) {
        Err(lucent::Error::Unconverged { diverged, .. }) => assert!(!diverged),
        other => panic!("{other:?}"),
    }
}

/// A forward-scattering cube (σ_t = 3, albedo 0.9, HG g = 0.6) under an oblique sun and in
/// vacuum: its scattered light is far from isotropic near the lit faces, so the angular
/// set matters.
fn forward_cube(n: usize) -> Problem {
    let geometry = GridGeometry::from_bounds([n, n, n], DVec3::ZERO, DVec3::splat(1.0)).unwrap();
    Problem::new(
        geometry,
        Medium {
            sigma_t: vec![Grid::filled(geometry, 3.0)],
            albedo: vec![Field::Constant(0.9)],
            phase: Phase::henyey_greenstein(0.6).unwrap(),
        },
        vec![Light::Directional {
            direction: DVec3::new(0.3, 0.2, -1.0).normalize(),
            irradiance: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
        None,
    )
    .unwrap()
}

/// The fewest directions: `dom` on the nested octahedral sets (128, 32, 8 directions),
/// each level's estimated angular error against the truth (the same grid with 512
/// directions), and the choice following the tolerance. Solvers without directions have
/// no angular family.
#[test]
fn fewest_directions_track_the_angular_error() {
    let registry = lucent::registry();
    let options = SolveOptions {
        relative_tolerance: 1e-9,
        ..SolveOptions::default()
    };
    let problem = forward_cube(12);
    let family = AngularFamily::of(&registry, "dom", &Params::default())
        .unwrap()
        .unwrap();
    assert_eq!(
        family.levels.iter().map(|l| l.0).collect::<Vec<_>>(),
        [128, 32, 8]
    );
    let choice = fewest_directions_meeting(&problem, &family, 1e-9, &options).unwrap();
    assert!(!choice.met && choice.chosen == 0, "{choice:?}");
    let finest: Params = toml::from_str("family = \"octahedral\"\norder = 3").unwrap();
    let truth = registry
        .build("dom", &finest)
        .unwrap()
        .solve(&problem, &options)
        .unwrap();
    for ((_, setting, solver), level) in family.levels.iter().zip(&choice.levels) {
        let solved = solver.solve(&problem, &options).unwrap();
        let error = relative_l2(solved.fluence(0), truth.fluence(0));
        eprintln!(
            "ANGULAR {setting}: estimated {:.3e}, true {error:.3e} (order {}, observed {})",
            level.estimated_error, choice.order, choice.observed
        );
        // As for the grid: within a factor of 3 of the truth (measured 0.7–1.2 with the
        // order observed at 2.7: ray effects shrink faster than the spacing squared here).
        assert!(
            (1.0 / 3.0..=3.0).contains(&(level.estimated_error / error)),
            "{level:?}: true {error:e}"
        );
    }
    let between = (choice.levels[0].estimated_error * choice.levels[1].estimated_error).sqrt();
    let picked = fewest_directions_meeting(&problem, &family, between, &options).unwrap();
    assert!(picked.met && picked.chosen == 0, "{picked:?}");
    let loose = choice.levels[2].estimated_error * 1.01;
    let picked = fewest_directions_meeting(&problem, &family, loose, &options).unwrap();
    assert!(picked.met && picked.chosen == 2, "{picked:?}");
    assert!(
        AngularFamily::of(&registry, "diffusion-mg", &Params::default())
            .unwrap()
            .is_none()
    );
}
