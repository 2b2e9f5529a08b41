//! Second order in the lattice spacing: manufactured solutions of
//! −D∇²φ + σ_a φ = Q₀ − 3∇·(D Q₁) on the unit cube (products of sines under a zero
//! Dirichlet wall, of cosines under a Robin wall φ + 2AD ∂φ/∂n = 0 whose wave number
//! solves tan(k/2) = 1/(2ADk)), drawn D, σ_a, A and first moments, solved at 8³ and 16³
//! cells: the observed order of the fluence's relative L2 error must be 2 (the collision
//! weights the source and sink by 1 − ω/2 and takes ρ̂ = Σf + S/2; without that the order
//! is 1, measured 1.08–1.16).

use lucent_core::Stopping;
use lucent_lbm::{
    Absorption, Collision, LatticeProblem, MarchSettings, Streaming, Velocities, Wall, march,
};
use proptest::prelude::*;

/// The relative L2 error at n³ cells.
fn error(n: usize, d: f64, sigma_a: f64, wall: Wall, moment: f64, velocities: Velocities) -> f64 {
    let h = 1.0 / n as f64;
    let pi = std::f64::consts::PI;
    let (k, robin) = match wall {
        Wall::Robin { a } => {
            let (mut lo, mut hi) = (1e-9, pi - 1e-9);
            for _ in 0..200 {
                let k = 0.5 * (lo + hi);
                if (k / 2.0).tan() < 1.0 / (2.0 * a * d * k) {
                    lo = k;
                } else {
                    hi = k;
                }
            }
            (0.5 * (lo + hi), true)
        }
        _ => (pi, false),
    };
    let f = |v: f64| {
        if robin {
            (k * (v - 0.5)).cos()
        } else {
            (k * v).sin()
        }
    };
    let df = |v: f64| {
        if robin {
            -(k * (v - 0.5)).sin()
        } else {
            (k * v).cos()
        }
    };
    let centre = |i: usize| (i as f64 + 0.5) * h;
    let (mut exact, mut source, mut first) = (Vec::new(), Vec::new(), Vec::new());
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let (fx, fy, fz) = (f(centre(x)), f(centre(y)), f(centre(z)));
                let phi = fx * fy * fz;
                // Q₁ = b f′(x) f(y) f(z) x̂ (Dirichlet only: it vanishes nowhere on the
                // walls, where a homogeneous Robin condition would not hold); its
                // divergence −b k f(x) f(y) f(z).
                let div = -moment * k * phi;
                exact.push(phi);
                source.push(((3.0 * k * k * d + sigma_a) * phi + 3.0 * d * div) * h);
                first.push([(moment * df(centre(x)) * fy * fz * h) as f32, 0.0, 0.0]);
            }
        }
    }
    let cells = n * n * n;
    let problem = LatticeProblem {
        dims: [n; 3],
        first: vec![(d / h) as f32; cells],
        second: vec![(sigma_a * h) as f32; cells],
        source: source.iter().map(|&q| q as f32).collect(),
        first_moment: if moment != 0.0 { first } else { Vec::new() },
        wall,
    };
    let settings = MarchSettings {
        velocities,
        collision: Collision::Trt,
        absorption: Absorption::True,
        streaming: Streaming::InPlace,
        stopping: Stopping {
            // Just above the floor of f32 populations' rounding (a step's relative
            // change stalls near 2e-7); the distance to the steady state is then below
            // the discretisation error at 16³.
            relative_tolerance: 4e-7,
            max_iterations: 20_000,
            ..Stopping::default()
        },
        blocks: None,
    };
    let m = march(&problem, &settings).unwrap();
    let residual = m.residuals.last().copied().unwrap_or(1.0);
    // Steady: converged, or stalled at the floor of the residual monitor (f32 populations
    // and the energy books). The floor depends on the coefficients: near 2e-7 for most,
    // 1.005e-6 at d = 0.194, σ_a = 0.51 under a Robin wall at 16³ (the regression case
    // below), where the march's error is still second order. Stalled: the last 1000
    // steps' smallest residual within 1 % of the 1000 before's, and below 1e-5.
    let stalled = |r: &[f64]| {
        let smallest = |w: &[f64]| w.iter().copied().fold(f64::INFINITY, f64::min);
        r.len() >= 2000 && {
            let (before, last) = r[r.len() - 2000..].split_at(1000);
            smallest(last) >= 0.99 * smallest(before) && smallest(last) < 1e-5
        }
    };
    assert!(
        m.stop_reason.is_converged() || residual < 1e-6 || stalled(&m.residuals),
        "{:?}",
        m.stop_reason
    );
    let (mut e, mut s) = (0.0, 0.0);
    for (a, b) in m.fluence.iter().zip(&exact) {
        e += (f64::from(*a) - b).powi(2);
        s += b * b;
    }
    (e / s).sqrt()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    #[test]
    fn the_steady_state_converges_at_second_order(
        d in 0.03f64..0.2,
        sigma_a in 0.5f64..4.0,
        robin in any::<bool>(),
        a in 1.0f64..3.0,
        moment in 0.0f64..0.5,
        d3q19 in any::<bool>(),
    ) {
        // D3Q19 under Robin walls is first order (its diagonal links meet the wall half a
        // cell along it, where the face's one ρ_w per cell does not hold; measured
        // 2.0e-3, 1.5e-3, 7.9e-4 at 8³, 16³, 32³, against D3Q7's 6.3e-3, 1.6e-3, 4.1e-4):
        // drawn under Dirichlet walls only.
        let d3q19 = d3q19 && !robin;
        let velocities = if d3q19 { Velocities::D3q19 } else { Velocities::D3q7 };
        let (wall, moment) = if robin {
            (Wall::Robin { a }, 0.0)
        } else {
            (Wall::Dirichlet { value: 0.0 }, moment)
        };
        let coarse = error(8, d, sigma_a, wall, moment, velocities);
        let fine = error(16, d, sigma_a, wall, moment, velocities);
        let order = (coarse / fine).log2();
        // Measured 1.98–2.00 (D3Q7) and up to 2.9 (D3Q19, whose error constant is smaller);
        // a first-order scheme gives about 1.
        prop_assert!(order > 1.75, "order {order:.2}: errors {coarse:.3e} → {fine:.3e}");
        prop_assert!(fine < 0.01, "error {fine:.3e} at 16³");
    }
}

/// A case the proptest drew whose residual stalls at 1.005e-6, above the 1e-6 the test
/// once asked for: its error is second order all the same.
#[test]
fn a_march_stalled_at_its_rounding_floor_is_steady() {
    let (d, sigma_a, wall) = (
        0.194_167_363_031_892_3,
        0.513_116_493_496_083_9,
        Wall::Robin {
            a: 2.573_881_849_377_940_5,
        },
    );
    let coarse = error(8, d, sigma_a, wall, 0.0, Velocities::D3q7);
    let fine = error(16, d, sigma_a, wall, 0.0, Velocities::D3q7);
    let order = (coarse / fine).log2();
    // Measured 6.13e-4 → 1.53e-4, order 2.00.
    assert!(order > 1.75 && fine < 0.01, "{coarse:e} → {fine:e}");
}
