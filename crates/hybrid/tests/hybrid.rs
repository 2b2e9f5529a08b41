//! The hybrid against its parts: energy closes part by part, a medium that does not
//! scatter gives the uncollided light alone, more swept orders converge to discrete
//! ordinates, and where the medium is thin single scattering by a sweep beats diffusion.
//!
//! The reference for accuracy is `dom` on the same S_N set and closure, converged: the
//! hybrid's only approximation against it is diffusion for the light that scattered more
//! than `orders` times, so the comparison isolates the coupling (against Monte Carlo the
//! ordinates' own error would be mixed in; the cross-check suite does that).

use glam::DVec3;
use lucent_core::{
    Boundary, Field, Light, Medium, Params, Problem, SolveError, SolveOptions, Solver, Spectrum,
};
use lucent_dom::DomSolver;
use lucent_grid::{Grid, GridGeometry};
use lucent_hybrid::HybridSolver;
use lucent_optics::Phase;
use proptest::prelude::*;

/// A cube of `n`³ cells on [−1, 1]³, σ_t uniform, under a sun along `sun` (and a sky of
/// radiance `sky` when positive).
fn cube(
    n: usize,
    sigma_t: f32,
    albedo: f32,
    g: f64,
    sun: DVec3,
    sky: f64,
    boundary: Boundary,
) -> Problem {
    let geometry =
        GridGeometry::from_bounds([n; 3], DVec3::splat(-1.0), DVec3::splat(1.0)).expect("geometry");
    let medium = Medium {
        sigma_t: vec![Grid::filled(geometry, sigma_t)],
        albedo: vec![Field::Constant(albedo)],
        phase: if g == 0.0 {
            Phase::Isotropic
        } else {
            Phase::henyey_greenstein(g).expect("g")
        },
    };
    let mut lights = vec![Light::Directional {
        direction: sun.normalize(),
        irradiance: Spectrum::Grey(1.0),
    }];
    if sky > 0.0 {
        lights.push(Light::Sky {
            radiance: Spectrum::Grey(sky),
        });
    }
    Problem::new(geometry, medium, lights, boundary, None).expect("problem")
}

fn options(tolerance: f64) -> SolveOptions {
    SolveOptions {
        relative_tolerance: tolerance,
        ..SolveOptions::default()
    }
}

/// ‖a − b‖₂ / ‖b‖₂ over the first channel.
fn relative_l2(a: &Grid, b: &Grid) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (x, y) in a.data().iter().zip(b.data()) {
        num += (f64::from(*x) - f64::from(*y)).powi(2);
        den += f64::from(*y).powi(2);
    }
    (num / den).sqrt()
}

fn dom(order: usize) -> DomSolver {
    dom_with(order, "diamond")
}

fn dom_with(order: usize, closure: &str) -> DomSolver {
    let params: Params =
        toml::from_str(&format!("order = {order}\nclosure = \"{closure}\"")).expect("params");
    DomSolver::from_params(&params).expect("dom")
}

/// Every part balances its own power, and the whole problem's balance is `dom`'s: the
/// only imbalance left is the uncollided cell integrals' (which both share), over
/// albedos, anisotropies, boundaries (vacuum, index-mismatched Robin, reflecting) and a
/// sky.
#[test]
fn energy_closes_part_by_part() {
    for (albedo, g, boundary, sky) in [
        (0.9, 0.0, Boundary::Vacuum, 0.0),
        (0.99, 0.7, Boundary::Vacuum, 0.1),
        (0.95, 0.3, Boundary::Robin { eta: 1.4 }, 0.0),
        (0.8, 0.5, Boundary::Neumann { flux: 0.0 }, 0.05),
    ] {
        // σ_t h = 0.5 under a vertical sun: the uncollided integrals close to ~1e-5
        // (lucent_dom::DomChannel).
        let problem = cube(16, 4.0, albedo, g, DVec3::NEG_Z, sky, boundary);
        for orders in [1, 3, 8] {
            let hybrid = HybridSolver::default().with_orders(orders).expect("orders");
            let (_, channels) = hybrid
                .solve_with_details(&problem, &options(1e-9))
                .expect("hybrid");
            let c = &channels[0];
            assert!(c.sweeps.len() <= orders);
            for (k, sweep) in c.sweeps.iter().enumerate() {
                // A sweep that does not reflect is exact arithmetic on f64 work, its
                // source f32: 1e-6. One that reflects iterates to 1e-9 relative.
                assert!(
                    sweep.relative_imbalance() < 1e-5,
                    "{boundary:?} albedo {albedo} g {g}: sweep {k} {sweep:?}"
                );
            }
            // The diffusion part: its solve's tolerance (1e-9) times the conditioning, and
            // f32 storage of its source.
            assert!(
                c.diffusion.relative_imbalance() < 1e-4,
                "{boundary:?} albedo {albedo} g {g}: diffusion {:?}",
                c.diffusion
            );
            // The scattered part of each sweep's collisions is the next sweep's source plus
            // what went to diffusion, and diffusion's source is all that went to it.
            assert_eq!(c.handed.len(), c.sweeps.len());
            for (k, sweep) in c.sweeps.iter().enumerate() {
                let scattered = albedo as f64 * sweep.absorbed;
                let next = c.sweeps.get(k + 1).map_or(0.0, |s| s.emitted);
                assert!(
                    (next + c.handed[k] - scattered).abs() <= 1e-5 * scattered,
                    "order {k}: {next} + {} vs {scattered}",
                    c.handed[k]
                );
            }
            let handed: f64 = c.handed.iter().sum();
            assert!(
                (c.diffusion.emitted - handed).abs() <= 1e-5 * handed,
                "{:?} vs {handed}",
                c.diffusion
            );
            assert!(
                c.balance.relative_imbalance() < 2e-3,
                "{boundary:?} albedo {albedo} g {g} orders {orders}: {:?}",
                c.balance
            );
        }
    }
}

/// Without scattering the hybrid's fluence is the uncollided light's, bit for bit as
/// `dom` gives it (the sweeps carry a zero source and diffusion a zero source), and no
/// power reaches the diffusion part.
#[test]
fn a_medium_that_does_not_scatter_gives_the_uncollided_light() {
    for sun in [DVec3::NEG_Z, DVec3::new(0.4, -0.3, -0.87)] {
        let problem = cube(13, 3.0, 0.0, 0.5, sun, 0.0, Boundary::Vacuum);
        let (hybrid, channels) = HybridSolver::default()
            .solve_with_details(&problem, &options(1e-8))
            .expect("hybrid");
        let ordinates = dom(8).solve(&problem, &options(1e-8)).expect("dom");
        assert_eq!(hybrid.fluence(0).data(), ordinates.fluence(0).data());
        assert_eq!(channels[0].diffusion.emitted, 0.0);
        assert_eq!(channels[0].diffused_share, 0.0);
    }
}

/// K swept orders leave diffusion the light that scattered more than K times: its share
/// falls with K, the fluence moves to `dom`'s on the same set, and with the share below
/// 10⁻⁵ the two agree to `dom`'s own tolerance. With the step closure: diamond's
/// set-to-zero fix-up is not linear, so fixing up order by order differs from fixing up
/// their sum (by 1.3e-4 here), which is a difference of closures, not of the coupling.
#[test]
fn more_swept_orders_converge_to_discrete_ordinates() {
    let problem = cube(
        12,
        2.0,
        0.7,
        0.6,
        DVec3::new(0.3, 0.2, -0.93),
        0.0,
        Boundary::Vacuum,
    );
    let reference = dom_with(4, "step")
        .solve(&problem, &options(1e-10))
        .expect("dom");
    let mut last_share = f64::INFINITY;
    let mut last_error = f64::INFINITY;
    for orders in [1, 2, 4, 8, 40] {
        let (solution, channels) = HybridSolver::default()
            .with_order(4)
            .and_then(|h| h.with_orders(orders))
            .expect("params")
            .with_closure(lucent_dom::Closure::Step)
            .solve_with_details(&problem, &options(1e-10))
            .expect("hybrid");
        let share = channels[0].diffused_share;
        let error = relative_l2(solution.fluence(0), reference.fluence(0));
        assert!(
            share < last_share,
            "orders {orders}: share {share} ≥ {last_share}"
        );
        assert!(
            error < last_error,
            "orders {orders}: error {error} ≥ {last_error}"
        );
        (last_share, last_error) = (share, error);
    }
    // 0.7⁴⁰ ≈ 6e-7 of the power is left to diffusion.
    assert!(last_share < 1e-5, "{last_share}");
    // dom converged to 1e-10; the sweeps' f32 sources over 40 orders: 1e-5.
    assert!(last_error < 1e-5, "{last_error}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]

    /// Where the medium is thin (optical depth 0.4 to 2 across the cube), single
    /// scattering by one sweep with diffusion for the rest is closer to converged
    /// ordinates than diffusion of the first collisions, over albedo, g and the sun's
    /// direction.
    #[test]
    fn single_scattering_beats_diffusion_where_thin(
        depth in 0.4f32..2.0,
        albedo in 0.5f32..0.98,
        g in 0.0f64..0.85,
        sx in -0.5f64..0.5,
        sy in -0.5f64..0.5,
    ) {
        let sigma_t = depth / 2.0;
        let problem = cube(12, sigma_t, albedo, g, DVec3::new(sx, sy, -1.0), 0.0, Boundary::Vacuum);
        let reference = dom(4).solve(&problem, &options(1e-8)).expect("dom");
        let hybrid = HybridSolver::default()
            .with_orders(1)
            .expect("orders")
            .solve(&problem, &options(1e-8))
            .expect("hybrid");
        let diffusion = lucent_diffusion::DiffusionSolver::custom("diffusion")
            .solve(&problem, &options(1e-8))
            .expect("diffusion");
        let e_hybrid = relative_l2(hybrid.fluence(0), reference.fluence(0));
        let e_diffusion = relative_l2(diffusion.fluence(0), reference.fluence(0));
        // Diffusion's error on the once-scattered light is what the sweep removes; what is
        // left is its error on light that scattered at least twice, a share of the
        // scattered light of about albedo × the probability that once-scattered light
        // collides again before it leaves, below 1 − e^{−τ} with τ the depth across the
        // whole cube. Measured over 40 draws: the ratio is 0.09–0.52, at most 0.78 of
        // this bound.
        let bound = f64::from(albedo) * (1.0 - (-f64::from(depth)).exp());
        prop_assert!(
            e_hybrid < bound * e_diffusion,
            "depth {depth} albedo {albedo} g {g}: hybrid {e_hybrid}, diffusion {e_diffusion}"
        );
    }
}

/// The sweeps stop once an order's scattered power is below the solve's tolerance of the
/// first order's, and hand that remainder to diffusion: in a thin medium far fewer than
/// `orders` sweeps run, over tolerances.
#[test]
fn sweeps_stop_at_the_tolerance() {
    let problem = cube(12, 0.5, 0.6, 0.4, DVec3::NEG_Z, 0.0, Boundary::Vacuum);
    for tolerance in [1e-3, 1e-6] {
        let (_, channels) = HybridSolver::default()
            .with_orders(64)
            .expect("orders")
            .solve_with_details(&problem, &options(tolerance))
            .expect("hybrid");
        let c = &channels[0];
        let first = c.sweeps[0].emitted + c.sweeps[0].inflow;
        let k = c.sweeps.len();
        // Each order keeps at most albedo × (1 − e^{−τ}) ≈ 0.38 of the last's power: the
        // tolerance is reached within log(tolerance)/log(0.38) + 1 orders.
        let bound = (tolerance.ln() / 0.38f64.ln()).ceil() as usize + 1;
        assert!(
            k <= bound,
            "tolerance {tolerance}: {k} sweeps, bound {bound}"
        );
        let handed = *c.handed.last().expect("a sweep");
        assert!(handed <= tolerance * first, "{handed} vs {first}");
        // Only the last sweep handed anything over.
        assert!(c.handed[..k - 1].iter().all(|&p| p == 0.0));
    }
}

/// Bad parameters are typed errors naming the parameter; an embedded body is refused
/// before anything runs.
#[test]
fn bad_parameters_and_unsupported_problems_are_refused() {
    for (text, name) in [
        ("orders = 0", "orders"),
        ("orders = 65", "orders"),
        ("order = 5", "order"),
        ("order = 18", "order"),
        ("block = 0", "block"),
    ] {
        let params: Params = toml::from_str(text).expect("toml");
        match HybridSolver::from_params(&params) {
            Err(SolveError::InvalidParameter { name: n, .. }) => assert_eq!(n, name, "{text}"),
            other => panic!("{text}: {other:?}"),
        }
    }
    let problem = cube(8, 1.0, 0.9, 0.0, DVec3::NEG_Z, 0.0, Boundary::Vacuum);
    let sdf = Grid::filled(*problem.geometry(), -1.0);
    let embedded = Problem::new(
        *problem.geometry(),
        problem.medium().clone(),
        problem.lights().to_vec(),
        Boundary::Vacuum,
        Some(sdf),
    )
    .expect("embedded");
    assert!(matches!(
        HybridSolver::default().solve(&embedded, &SolveOptions::default()),
        Err(SolveError::Unsupported { .. })
    ));
}
