//! Zhang & Ma's checkable cases (Zhang & Ma T1–T6, T12, T13 of docs/reference-cases.md) and the upwind scheme's
//! stability, known and enforced.

use glam::DVec3;
use lucent_core::StopReason;
use lucent_core::Stopping;
use lucent_explicit::convection::{Edges, Light, Model, Sweep, UpwindSettings, propagate};
use lucent_explicit::scatter::{StepSolver, diffuse};
use lucent_explicit::{ExplicitError, Lattice, stability};
use proptest::prelude::*;

fn distant(direction: DVec3) -> Light {
    Light::Distant {
        direction,
        density: 1.0,
    }
}

#[test]
fn t1_vacuum_transport_is_exact() {
    // A constant field is an exact discrete fixed point: no decay with depth, to rounding.
    let lattice = Lattice::new([12, 10, 9], 1.0).unwrap();
    for dir in [
        DVec3::X,
        DVec3::new(1.0, 1.0, 1.0),
        DVec3::new(-0.3, 0.5, -0.8),
    ] {
        for sweep in [
            Sweep::Layers {
                iterations: 5,
                warm_start: true,
            },
            Sweep::Jacobi,
        ] {
            let settings = UpwindSettings {
                sweep,
                ..UpwindSettings::default()
            };
            let out = propagate(
                &lattice,
                &vec![0.0; lattice.len()],
                &distant(dir),
                &settings,
            )
            .unwrap();
            assert!(out.stop_reason.is_converged(), "{:?}", out.stop_reason);
            let worst = out
                .density
                .iter()
                .map(|v| (v - 1.0).abs())
                .fold(0.0, f64::max);
            assert!(worst < 1e-9, "{dir:?} {sweep:?}: {worst}");
        }
    }
}

#[test]
fn t2_discrete_beer_lambert() {
    // ρ at the tenth cell = q¹⁰, q = (1 − σ_a)/(1 + σ_a) at C = ½ (Zhang & Ma T2); and
    // for other C, q = (1 − σ_a)C/(σ_a + C − σ_a C).
    let lattice = Lattice::new([32, 1, 1], 1.0).unwrap();
    for (sa, expected) in [
        (0.01, 0.818725),
        (0.1, 0.134431),
        (0.3, 2.049e-3),
        (0.5, 1.6935e-5),
    ] {
        let settings = UpwindSettings {
            stopping: Stopping {
                relative_tolerance: 1e-15,
                ..UpwindSettings::default().stopping
            },
            ..UpwindSettings::default()
        };
        let out = propagate(&lattice, &[sa; 32], &distant(DVec3::X), &settings).unwrap();
        let q: f64 = (1.0 - sa) / (1.0 + sa);
        assert!(
            (out.density[9] - q.powi(10)).abs() <= 1e-10 * q.powi(10),
            "{sa}: {} {} {:?}",
            out.density[9],
            q.powi(10),
            out.stop_reason
        );
        // The note prints 4–6 digits.
        assert!(
            (out.density[9] / expected - 1.0).abs() < 1e-4,
            "{sa}: {}",
            out.density[9]
        );
    }
    for (c, ratio) in [(0.25, 0.5), (0.5, 2.0 / 3.0), (1.0, 0.8)] {
        let settings = UpwindSettings {
            courant: Some(c),
            stopping: Stopping {
                relative_tolerance: 1e-15,
                ..UpwindSettings::default().stopping
            },
            ..UpwindSettings::default()
        };
        let out = propagate(&lattice, &[0.2; 32], &distant(DVec3::X), &settings).unwrap();
        assert!(
            (out.density[5] / out.density[4] - ratio).abs() < 1e-12,
            "C = {c}"
        );
    }
}

#[test]
fn t3_an_opaque_block_casts_an_exact_hard_shadow() {
    // σ_a = 1 on a 20-cell block: exactly 0 in its shadow 150 cells downstream, exactly 1
    // beside it.
    let lattice = Lattice::new([180, 40, 1], 1.0).unwrap();
    let mut sa = vec![0.0; lattice.len()];
    for j in 10..30 {
        for i in 5..25 {
            sa[i + 180 * j] = 1.0;
        }
    }
    let out = propagate(
        &lattice,
        &sa,
        &distant(DVec3::X),
        &UpwindSettings::default(),
    )
    .unwrap();
    for j in 0..40 {
        let v = out.density[175 + 180 * j];
        if (10..30).contains(&j) {
            assert_eq!(v, 0.0, "row {j}");
        } else {
            assert!((v - 1.0).abs() < 1e-12, "row {j}: {v}");
        }
    }
}

/// Growth per step of a checkerboard on a periodic 8³ grid under global Jacobi steps.
fn checkerboard_growth(courant: f64, direction: DVec3, sigma_a: f64) -> f64 {
    let lattice = Lattice::new([8; 3], 1.0).unwrap();
    let initial: Vec<f64> = (0..lattice.len())
        .map(|c| {
            let [i, j, k] = lattice.coords(c);
            if (i + j + k) % 2 == 0 { 1.0 } else { -1.0 }
        })
        .collect();
    let run = |steps| {
        let settings = UpwindSettings {
            courant: Some(courant),
            sweep: Sweep::Jacobi,
            edges: Edges::Periodic,
            stopping: Stopping {
                relative_tolerance: 0.0,
                max_iterations: steps,
                ..Stopping::default()
            },
            allow_unstable: true,
            initial: Some(initial.clone()),
            ..UpwindSettings::default()
        };
        let out = propagate(
            &lattice,
            &vec![sigma_a; 512],
            &distant(direction),
            &settings,
        )
        .unwrap();
        out.density.iter().fold(0.0f64, |a, b| a.max(b.abs()))
    };
    run(5) / run(4)
}

#[test]
fn t4_growth_factors_of_the_checkerboard() {
    // Zhang & Ma T4's table (docs/reference-cases.md), within 1%; and the closed form of `stability::upwind`.
    let diagonal = DVec3::ONE.normalize();
    for (direction, c, sa, expected) in [
        (diagonal, 0.5, 0.0, 0.7321),
        (diagonal, 0.5, 0.1, 0.6588),
        (diagonal, 0.6, 0.0, 1.0785),
        (diagonal, 0.6, 0.1, 0.9706),
        (diagonal, 1.0, 0.0, 2.4641),
        (DVec3::X, 1.0, 0.0, 1.0),
        (DVec3::X, 1.1, 0.0, 1.2),
    ] {
        let g = checkerboard_growth(c, direction, sa);
        assert!(
            (g / expected - 1.0).abs() < 0.01,
            "C = {c}, σ_a = {sa}: {g}"
        );
        let formula = stability::upwind::checkerboard_growth(c, direction, sa);
        assert!((formula / expected - 1.0).abs() < 1e-4);
    }
    // The paper's C ≤ 1 admits C = 0.6 on the diagonal; the correct bound refuses it.
    let lattice = Lattice::new([8; 3], 1.0).unwrap();
    let settings = UpwindSettings {
        courant: Some(0.6),
        ..UpwindSettings::default()
    };
    match propagate(&lattice, &[0.0; 512], &distant(diagonal), &settings) {
        Err(ExplicitError::Unstable {
            limit, requested, ..
        }) => {
            assert!((limit - 1.0 / 3f64.sqrt()).abs() < 1e-12);
            assert_eq!(requested, 0.6);
        }
        other => panic!("expected Unstable, got {other:?}"),
    }
}

#[test]
fn t6_warm_and_cold_starts_per_layer() {
    // 1-D, k Jacobi updates per layer from zero: ρ at layer 128 = (1 − 2⁻ᵏ)¹²⁸ (Zhang & Ma
    // T6: 2.58e-4, 1.72e-2, 0.882); from the upstream layer: exactly 1.
    let lattice = Lattice::new([128, 1, 1], 1.0).unwrap();
    let one_pass = |iterations, warm_start, sa: f64| {
        let settings = UpwindSettings {
            sweep: Sweep::Layers {
                iterations,
                warm_start,
            },
            stopping: Stopping {
                max_iterations: 1,
                ..UpwindSettings::default().stopping
            },
            ..UpwindSettings::default()
        };
        propagate(&lattice, &[sa; 128], &distant(DVec3::X), &settings)
            .unwrap()
            .density
    };
    for (k, expected) in [(4, 2.58e-4), (5, 1.72e-2), (10, 0.882)] {
        let v = one_pass(k, false, 0.0)[127];
        let exact = (1.0 - 0.5f64.powi(k as i32)).powi(128);
        assert!((v / exact - 1.0).abs() < 1e-9, "k = {k}: {v} vs {exact}");
        assert!((v / expected - 1.0).abs() < 3e-3, "k = {k}: {v}");
        assert!((one_pass(k, true, 0.0)[127] - 1.0).abs() < 1e-12);
    }
    // σ_a = 0.1, warm start, layer 64: 4.73e-6 (k = 4), 3.44e-6 (k = 5), 2.645e-6 converged.
    for (k, expected) in [(4, 4.73e-6), (5, 3.44e-6), (60, 2.645e-6)] {
        let v = one_pass(k, true, 0.1)[63];
        assert!((v / expected - 1.0).abs() < 3e-3, "k = {k}: {v}");
    }
}

#[test]
fn point_lights_inside_and_outside() {
    // Paper model, vacuum: an internal light fills the grid with exactly ρ_P (T8: no 1/r²
    // fall-off); the seed is the 27 cells within 2Δx when the light sits on a centre.
    // Conservative model: ρ r² is constant along rays to within the scheme's first-order
    // error.
    let lattice = Lattice::new([33; 3], 1.0).unwrap();
    let centre = DVec3::splat(16.5);
    let light = Light::Point {
        position: centre,
        density: 1.0,
        falloff: None,
    };
    let settings = UpwindSettings {
        sweep: Sweep::Jacobi,
        ..UpwindSettings::default()
    };
    let out = propagate(&lattice, &vec![0.0; lattice.len()], &light, &settings).unwrap();
    assert!(out.stop_reason.is_converged());
    let (lo, hi) = out
        .density
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    assert!(
        (lo - 1.0).abs() < 1e-9 && (hi - 1.0).abs() < 1e-9,
        "{lo} {hi}"
    );
    let conservative = UpwindSettings {
        model: Model::Conservative,
        sweep: Sweep::Jacobi,
        ..UpwindSettings::default()
    };
    let out = propagate(&lattice, &vec![0.0; lattice.len()], &light, &conservative).unwrap();
    assert!(out.stop_reason.is_converged(), "{:?}", out.stop_reason);
    // Along the +x axis the fall-off exponent between r = 5.5 and 14.5 cells: 2 in the
    // continuum; first-order upwind on the diverging flow gives 1.74 at this resolution
    // (measured), against 0 for the paper's model.
    let at = |i: usize| out.density[i + 33 * (16 + 33 * 16)];
    let exponent = (at(22) / at(31)).ln() / (14.5f64 / 5.5).ln();
    assert!((1.6..2.2).contains(&exponent), "{exponent}");
    // An external light: Dirichlet exactly where n·(x − x_P) < 0 (T10) — the faces that
    // see it; here the light is beyond the x = 0 face, so the other faces hold nothing.
    let outside = Light::Point {
        position: DVec3::new(-10.0, 16.5, 16.5),
        density: 1.0,
        falloff: None,
    };
    let out = propagate(&lattice, &vec![0.0; lattice.len()], &outside, &settings).unwrap();
    assert!(out.stop_reason.is_converged());
    assert!(out.density.iter().all(|&v| (v - 1.0).abs() < 1e-9));
}

#[test]
fn t12_implicit_diffusion_conserves_mass() {
    // Random 24³ field, a = σ_s Δt/Δx² = 10: mass kept to 1e-10 relative (the note: 13
    // digits), and the field smoothed (standard deviation 0.289 → 0.0136 in the note's run).
    let lattice = Lattice::new([24; 3], 1.0).unwrap();
    let mut state = 12345u64;
    let field: Vec<f64> = (0..lattice.len())
        .map(|_| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        })
        .collect();
    let out = diffuse(&lattice, &field, 10.0, 1.0, 1, StepSolver::default()).unwrap();
    assert!(out.stop_reason.is_converged());
    let before: f64 = field.iter().sum();
    let after: f64 = out.field.iter().sum();
    assert!((after / before - 1.0).abs() < 1e-10, "{before} {after}");
    let sd = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
    };
    assert!((sd(&field) - 0.289).abs() < 0.01);
    assert!(sd(&out.field) < 0.02, "{}", sd(&out.field));
}

#[test]
fn t13_impulse_variance_is_two_sigma_t() {
    // A unit impulse, backward Euler in 1 or 4 steps to t: mass 1 and per-axis variance
    // exactly 2σ_s t/Δx² (here 2 cells²). The discrete kernel of (I − aΔ)⁻¹ decays like
    // e^{−0.96 r} at a = 1, so the 41³ box's walls, 20 cells away, shift it by ~2e-7.
    let lattice = Lattice::new([41; 3], 1.0).unwrap();
    let mut field = vec![0.0; lattice.len()];
    let centre = 20 + 41 * (20 + 41 * 20);
    field[centre] = 1.0;
    for steps in [1, 4] {
        let out = diffuse(&lattice, &field, 1.0, 1.0, steps, StepSolver::default()).unwrap();
        let mass: f64 = out.field.iter().sum();
        let variance: f64 = out
            .field
            .iter()
            .enumerate()
            .map(|(c, v)| v * (lattice.coords(c)[0] as f64 - 20.0).powi(2))
            .sum();
        assert!((mass - 1.0).abs() < 1e-10);
        assert!((variance - 2.0).abs() < 1e-6, "{steps} steps: {variance}");
    }
    // The multigrid route gives the same field to its tolerance.
    let gs = diffuse(&lattice, &field, 2.0, 1.0, 1, StepSolver::default()).unwrap();
    let mg = diffuse(
        &lattice,
        &field,
        2.0,
        1.0,
        1,
        StepSolver::Multigrid { tolerance: 1e-10 },
    )
    .unwrap();
    let diff = gs
        .field
        .iter()
        .zip(&mg.field)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(diff < 1e-7, "{diff}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn upwind_below_the_bound_is_bounded_and_non_negative(
        dx in -1.0f64..1.0, dy in -1.0f64..1.0, dz in 0.1f64..1.0,
        fraction in 0.1f64..0.95, sigma in 0.0f64..1.0, seed in 0u64..1000,
    ) {
        // T5: at C ≤ 0.95 × the correct bound, 0 ≤ ρ ≤ ρ_D at every step.
        let direction = DVec3::new(dx, dy, dz).normalize();
        let courant = fraction * stability::upwind::courant_limit(direction);
        let lattice = Lattice::new([10, 9, 8], 1.0).unwrap();
        let sa: Vec<f64> = (0..lattice.len())
            .map(|c| if ((c as u64 * 2654435761) ^ seed).is_multiple_of(7) { sigma } else { 0.1 * sigma })
            .collect();
        for steps in [1, 7, 40] {
            let settings = UpwindSettings {
                courant: Some(courant),
                sweep: Sweep::Jacobi,                stopping: Stopping { relative_tolerance: 0.0, max_iterations: steps, ..Stopping::default() },
                ..UpwindSettings::default()
            };
            let out = propagate(&lattice, &sa, &distant(direction), &settings).unwrap();
            prop_assert!(out.density.iter().all(|&v| (-1e-12..=1.0 + 1e-12).contains(&v)));
        }
    }

    #[test]
    fn upwind_beyond_the_bound_is_refused_or_stopped(
        dx in -1.0f64..1.0, dy in -1.0f64..1.0, dz in 0.3f64..1.0, factor in 1.1f64..3.0,
    ) {
        // ≥ 1.1 × the bound: refused; forced with allow_unstable, the growth monitor stops
        // it with DivergedGrowth and a finite field (periodic checkerboard, no absorption).
        let direction = DVec3::new(dx, dy, dz).normalize();
        let courant = factor * stability::upwind::courant_limit(direction);
        let lattice = Lattice::new([8; 3], 1.0).unwrap();
        let refused = propagate(&lattice, &[0.0; 512], &distant(direction), &UpwindSettings {
            courant: Some(courant),
            ..UpwindSettings::default()
        });
        let is_unstable = matches!(refused, Err(ExplicitError::Unstable { .. }));
        prop_assert!(is_unstable);
        let initial: Vec<f64> = (0..512)
            .map(|c| { let [i, j, k] = lattice.coords(c); if (i + j + k) % 2 == 0 { 1.0 } else { -1.0 } })
            .collect();
        let out = propagate(&lattice, &[0.0; 512], &distant(direction), &UpwindSettings {
            courant: Some(courant),
            sweep: Sweep::Jacobi,
            edges: Edges::Periodic,            stopping: Stopping { relative_tolerance: 0.0, max_iterations: 100_000, ..Stopping::default() },
            allow_unstable: true,
            initial: Some(initial),
            ..UpwindSettings::default()
        }).unwrap();
        let diverged = matches!(out.stop_reason, StopReason::DivergedGrowth { .. });
        prop_assert!(diverged, "{:?}", out.stop_reason);
        prop_assert!(out.density.iter().all(|v| v.is_finite()));
    }
}
