//! The `direct` solver against closed forms: Beer–Lambert along axis-aligned beams, the
//! exact optical depth of a linear ramp, inverse-square point lights, the sky in vacuum, and
//! second-order convergence for an oblique beam through a smooth medium.

use std::f64::consts::PI;

use glam::DVec3;
use lucent_core::{
    Boundary, DirectSolver, Field, Light, Medium, Problem, SolveError, SolveOptions, Solver,
    Spectrum,
};
use lucent_grid::{Grid, GridGeometry};
use lucent_optics::Phase;
use proptest::prelude::*;

fn medium(sigma_t: Grid) -> Medium {
    Medium {
        sigma_t: vec![sigma_t],
        albedo: vec![Field::Constant(0.8)],
        phase: Phase::Isotropic,
    }
}

fn solve(geometry: GridGeometry, sigma_t: Grid, lights: Vec<Light>) -> lucent_core::Solution {
    let problem = Problem::new(geometry, medium(sigma_t), lights, Boundary::Vacuum, None).unwrap();
    DirectSolver::default()
        .solve(&problem, &SolveOptions::default())
        .unwrap()
}

proptest! {
    #[test]
    fn axis_aligned_beam_through_a_homogeneous_slab_is_beer_lambert(
        sigma in 0.01f64..8.0,
        n in 4usize..40,
        axis in 0usize..3,
        backwards in any::<bool>(),
    ) {
        let mut dims = [3, 3, 3];
        dims[axis] = n;
        let geometry = GridGeometry::new(dims, DVec3::splat(1.0 / n as f64), DVec3::ZERO).unwrap();
        let mut direction = DVec3::ZERO;
        direction[axis] = if backwards { -1.0 } else { 1.0 };
        let sun = Light::Directional { direction, irradiance: Spectrum::Grey(2.0) };
        let solution = solve(geometry, Grid::filled(geometry, sigma as f32), vec![sun]);
        for index in 0..geometry.voxel_count() {
            let c = geometry.coords(index);
            let depth = (c[axis] as f64 + 0.5) / n as f64;
            let depth = if backwards { 1.0 - depth } else { depth };
            let exact = 2.0 * (-(sigma as f32 as f64) * depth).exp();
            // The tolerance, 1e-4; f32 storage limits agreement to ~1e-7 relative.
            prop_assert!((f64::from(solution.fluence(0).data()[index]) - exact).abs() < 1e-4 * exact.max(1e-3), "cell {c:?}");
        }
    }
}

#[test]
fn linear_ramp_gives_the_analytic_optical_depth() {
    // σ_t(x) = a + b x sampled at cell centres; the trilinear medium is exactly linear
    // between the first and last centre and constant (clamped) in the half cells outside.
    let n = 20;
    let h = 1.0 / n as f64;
    let (a, b) = (0.5, 3.0);
    let geometry = GridGeometry::new([n, 2, 2], DVec3::splat(h), DVec3::ZERO).unwrap();
    let ramp = Grid::from_fn(geometry, |p| (a + b * p.x) as f32);
    let sun = Light::Directional {
        direction: DVec3::X,
        irradiance: Spectrum::Grey(1.0),
    };
    let solution = solve(geometry, ramp.clone(), vec![sun]);
    let sigma = |x: f64| f64::from(ramp.sample_trilinear(DVec3::new(x, 0.5 * h, 0.5 * h)));
    for i in 0..n {
        let x = (i as f64 + 0.5) * h;
        // ∫₀ˣ σ: the clamped half cell [0, h/2] at σ(h/2), then the linear part.
        let c0 = 0.5 * h;
        let sigma0 = a + b * c0;
        let tau = sigma0 * c0 + (a * (x - c0) + 0.5 * b * (x * x - c0 * c0));
        let exact = (-tau).exp();
        let got = f64::from(solution.fluence(0).get(i, 0, 0).unwrap());
        assert!(
            (got - exact).abs() < 1e-6 * exact.max(1e-3),
            "x = {x}: {got} vs {exact} (σ(x) = {})",
            sigma(x)
        );
    }
}

#[test]
fn point_light_in_vacuum_falls_off_as_inverse_square() {
    let geometry = GridGeometry::new([8, 8, 8], DVec3::splat(0.25), DVec3::ZERO).unwrap();
    let position = DVec3::new(-1.0, 1.0, 1.0);
    let lamp = Light::Point {
        position,
        intensity: Spectrum::Grey(5.0),
    };
    let solution = solve(geometry, Grid::filled(geometry, 0.0), vec![lamp]);
    for index in 0..geometry.voxel_count() {
        let [i, j, k] = geometry.coords(index);
        let r2 = (geometry.cell_centre(i, j, k) - position).length_squared();
        assert!((f64::from(solution.fluence(0).data()[index]) - 5.0 / r2).abs() < 1e-6 * 5.0 / r2);
    }
}

#[test]
fn sky_in_vacuum_gives_four_pi_radiance_and_isotropic_inscattering() {
    let geometry = GridGeometry::new([6, 6, 6], DVec3::splat(1.0), DVec3::ZERO).unwrap();
    let sky = Light::Sky {
        radiance: Spectrum::Rgb([0.1, 0.2, 0.3]),
    };
    let solution = solve(geometry, Grid::filled(geometry, 0.0), vec![sky]);
    assert_eq!(solution.fluence.len(), 3);
    for c in 0..3 {
        let expected = 4.0 * PI * [0.1, 0.2, 0.3][c];
        assert!(
            solution
                .fluence(c)
                .data()
                .iter()
                .all(|&v| (f64::from(v) - expected).abs() < 1e-5)
        );
        // Isotropic radiance L scatters back as L whatever the direction.
        let l = solution.inscattered(c, DVec3::splat(3.0), DVec3::new(0.0, 0.6, 0.8));
        assert!((l - [0.1, 0.2, 0.3][c]).abs() < 1e-6);
    }
}

#[test]
fn spot_lights_are_dark_outside_their_cone() {
    let geometry =
        GridGeometry::new([9, 9, 1], DVec3::splat(1.0), DVec3::new(-4.5, -0.5, -0.5)).unwrap();
    let spot = Light::Spot {
        position: DVec3::new(0.0, -10.0, 0.0),
        direction: DVec3::Y,
        intensity: Spectrum::Grey(100.0),
        inner_angle: 0.1,
        outer_angle: 0.2,
    };
    let solution = solve(geometry, Grid::filled(geometry, 0.0), vec![spot]);
    // On the axis, 14 from the light: full intensity / r²; far off axis
    // (atan(4/10) = 0.38 rad > outer angle): nothing.
    let on_axis = solution.fluence(0).get(4, 4, 0).unwrap();
    assert!((f64::from(on_axis) - 100.0 / 196.0).abs() < 1e-6);
    assert_eq!(solution.fluence(0).get(0, 0, 0), Some(0.0));
}

#[test]
fn phase_weighted_single_scattering_from_the_transmittance() {
    let geometry = GridGeometry::new([4, 4, 4], DVec3::splat(0.25), DVec3::ZERO).unwrap();
    let mut m = medium(Grid::filled(geometry, 1.0));
    m.phase = Phase::henyey_greenstein(0.7).unwrap();
    let sun = Light::Directional {
        direction: DVec3::Z,
        irradiance: Spectrum::Grey(1.0),
    };
    let problem = Problem::new(geometry, m, vec![sun], Boundary::Vacuum, None).unwrap();
    let solution = DirectSolver::default()
        .solve(&problem, &SolveOptions::default())
        .unwrap();
    let x = geometry.cell_centre(1, 2, 3);
    let t = (-(3.5f64 * 0.25)).exp();
    let hg = Phase::henyey_greenstein(0.7).unwrap();
    use lucent_optics::PhaseFunction;
    for omega in [DVec3::Z, -DVec3::Z, DVec3::X] {
        let expected = hg.eval(DVec3::Z, omega) * t;
        assert!(
            (solution.inscattered(0, x, omega) - expected).abs() < 1e-6 * expected.max(1e-3),
            "{omega}"
        );
    }
}

#[test]
fn oblique_beams_converge_at_second_order() {
    // A smooth medium σ_t(p) = 1 + ½ sin(2πx) cos(πy) + z on the unit cube, lit obliquely.
    // The solver integrates the trilinear interpolant of the cell values exactly, so its
    // error at cell centres is the interpolation error of σ_t along the ray, O(h²) (the
    // clamped half cells at the faces contribute O(h²) too). Measured max errors:
    // 1.03e-2, 2.62e-3, 6.67e-4, 1.69e-4 at n = 8, 16, 32, 64 (order 1.98).
    // (Interpolating the transmittance grid between centres is only first order where the
    // face the ray enters through changes: e^{−τ} has a kink there.)
    let sigma = |p: DVec3| 1.0 + 0.5 * (2.0 * PI * p.x).sin() * (PI * p.y).cos() + p.z;
    let direction = DVec3::new(0.6, 0.3, 0.742_6).normalize();
    let exact_transmittance = |x: DVec3| {
        // Back along the ray to the face it entered through; Simpson on 2000 panels is
        // exact to ~1e-12 for this smooth integrand.
        let length = (0..3)
            .map(|a| x[a] / direction[a])
            .fold(f64::INFINITY, f64::min);
        let panels = 2000;
        let ds = length / panels as f64;
        let f = |s: f64| sigma(x - direction * s);
        let tau: f64 = (0..panels)
            .map(|i| {
                let s = i as f64 * ds;
                ds / 6.0 * (f(s) + 4.0 * f(s + 0.5 * ds) + f(s + ds))
            })
            .sum();
        (-tau).exp()
    };
    let mut errors = Vec::new();
    for n in [8usize, 16, 32] {
        let geometry =
            GridGeometry::new([n; 3], DVec3::splat(1.0 / n as f64), DVec3::ZERO).unwrap();
        let grid = Grid::from_fn(geometry, |p| sigma(p) as f32);
        let sun = Light::Directional {
            direction,
            irradiance: Spectrum::Grey(1.0),
        };
        let solution = solve(geometry, grid, vec![sun]);
        let worst = (0..geometry.voxel_count())
            .map(|index| {
                let [i, j, k] = geometry.coords(index);
                let x = geometry.cell_centre(i, j, k);
                (f64::from(solution.fluence(0).data()[index]) - exact_transmittance(x)).abs()
            })
            .fold(0.0, f64::max);
        errors.push(worst);
    }
    let orders: Vec<f64> = errors.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
    assert!(
        orders.iter().all(|&p| (1.8..2.2).contains(&p)),
        "errors {errors:?}, observed orders {orders:?}"
    );
}

#[test]
fn unsupported_features_are_refused_by_name() {
    let geometry = GridGeometry::new([4, 4, 4], DVec3::ONE, DVec3::ZERO).unwrap();
    let sun = Light::Directional {
        direction: DVec3::X,
        irradiance: Spectrum::Grey(1.0),
    };
    let robin = Problem::new(
        geometry,
        medium(Grid::filled(geometry, 1.0)),
        vec![sun.clone()],
        Boundary::Robin { eta: 1.3 },
        None,
    )
    .unwrap();
    match DirectSolver::default().solve(&robin, &SolveOptions::default()) {
        Err(SolveError::Unsupported { solver, feature }) => {
            assert_eq!(solver, "direct");
            assert!(feature.contains("Robin"), "{feature}");
        }
        other => panic!("expected Unsupported, got {other:?}"),
    }
    let glow = Light::Emission {
        grid: Grid::filled(geometry, 1.0),
        scale: Spectrum::Grey(1.0),
    };
    let emissive = Problem::new(
        geometry,
        medium(Grid::filled(geometry, 1.0)),
        vec![glow],
        Boundary::Vacuum,
        None,
    )
    .unwrap();
    assert!(matches!(
        DirectSolver::default().solve(&emissive, &SolveOptions::default()),
        Err(SolveError::Unsupported { .. })
    ));
    // Invalid problems never get that far.
    let mut bad = medium(Grid::filled(geometry, -1.0));
    assert!(
        Problem::new(
            geometry,
            bad.clone(),
            vec![sun.clone()],
            Boundary::Vacuum,
            None
        )
        .is_err()
    );
    bad.sigma_t = vec![Grid::filled(geometry, 1.0)];
    bad.albedo = vec![Field::Constant(1.5)];
    assert!(Problem::new(geometry, bad, vec![sun], Boundary::Vacuum, None).is_err());
    let tilted = Light::Directional {
        direction: DVec3::new(1.0, 1.0, 0.0),
        irradiance: Spectrum::Grey(1.0),
    };
    assert!(
        Problem::new(
            geometry,
            medium(Grid::filled(geometry, 1.0)),
            vec![tilted],
            Boundary::Vacuum,
            None
        )
        .is_err()
    );
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    let geometry = GridGeometry::new([12, 10, 8], DVec3::splat(0.1), DVec3::ZERO).unwrap();
    let cloud = Grid::from_fn(geometry, |p| (5.0 * (p.x * 7.0).sin().abs() * p.y) as f32);
    let lights = vec![
        Light::Directional {
            direction: DVec3::new(0.3, -0.4, 0.866).normalize(),
            irradiance: Spectrum::Grey(1.0),
        },
        Light::Sky {
            radiance: Spectrum::Grey(0.2),
        },
    ];
    let problem = Problem::new(geometry, medium(cloud), lights, Boundary::Vacuum, None).unwrap();
    let one = DirectSolver::default()
        .solve(
            &problem,
            &SolveOptions {
                threads: Some(1),
                ..Default::default()
            },
        )
        .unwrap();
    let two = DirectSolver::default()
        .solve(
            &problem,
            &SolveOptions {
                threads: Some(2),
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!(one.fluence, two.fluence);
    assert!(one.report.stop_reason.is_converged());
}
