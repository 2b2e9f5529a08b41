//! Phase functions: normalisation, mean cosine, Legendre moments, exact sampling.

use std::f64::consts::PI;

use glam::DVec3;
use lucent_optics::integrate::adaptive;
use lucent_optics::phase::{DoubleHenyeyGreenstein, HenyeyGreenstein, Isotropic, Rayleigh};
use lucent_optics::{Phase, PhaseFunction};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

const G_VALUES: [f64; 6] = [-0.9, -0.3, 0.0, 0.3, 0.9, 0.99];

/// 2π ∫ f(μ) p(μ) dμ over [−1, 1], to 1e-12 absolute.
fn sphere_integral(phase: &impl PhaseFunction, f: impl Fn(f64) -> f64) -> f64 {
    adaptive(
        |mu| 2.0 * PI * phase.eval_cos(mu) * f(mu),
        -1.0,
        1.0,
        1e-12,
        0.0,
    )
}

fn all_phases() -> Vec<(String, Phase)> {
    let mut phases: Vec<(String, Phase)> = G_VALUES
        .iter()
        .map(|&g| (format!("HG({g})"), Phase::henyey_greenstein(g).unwrap()))
        .collect();
    phases.push((
        "DHG(0.9, -0.5, 0.7)".into(),
        Phase::double_henyey_greenstein(0.9, -0.5, 0.7).unwrap(),
    ));
    phases.push(("Rayleigh".into(), Phase::Rayleigh));
    phases.push(("isotropic".into(), Phase::Isotropic));
    phases
}

#[test]
fn every_phase_function_integrates_to_one_with_mean_cosine_g() {
    // The tolerance, 1e-6; the quadrature itself is good to 1e-12, so any failure
    // is in the phase function.
    for (name, phase) in all_phases() {
        let norm = sphere_integral(&phase, |_| 1.0);
        assert!((norm - 1.0).abs() < 1e-6, "{name}: ∫p dω = {norm}");
        let g = sphere_integral(&phase, |mu| mu);
        assert!(
            (g - phase.mean_cosine()).abs() < 1e-6,
            "{name}: <cos> = {g}, claimed {}",
            phase.mean_cosine()
        );
    }
    for g in G_VALUES {
        assert!((Phase::henyey_greenstein(g).unwrap().mean_cosine() - g).abs() < 1e-15);
    }
}

/// A phase function that hides its closed-form moments, so the trait's numerical default
/// is used.
struct NumericMoments<P>(P);

impl<P: PhaseFunction> PhaseFunction for NumericMoments<P> {
    fn eval_cos(&self, mu: f64) -> f64 {
        self.0.eval_cos(mu)
    }
    fn sample_cos(&self, u: f64) -> f64 {
        self.0.sample_cos(u)
    }
    fn mean_cosine(&self) -> f64 {
        self.0.mean_cosine()
    }
}

fn assert_moments_match_quadrature<P: PhaseFunction + Copy>(name: &str, phase: P) {
    let closed = phase.legendre_moments(12);
    let numeric = NumericMoments(phase).legendre_moments(12);
    assert_eq!(closed.len(), 13);
    assert!(
        (closed[0] - 1.0).abs() < 1e-15,
        "{name}: χ0 = {}",
        closed[0]
    );
    for (l, (c, n)) in closed.iter().zip(&numeric).enumerate() {
        // The adaptive rule's absolute tolerance is 1e-12 per moment.
        assert!(
            (c - n).abs() < 1e-10,
            "{name} χ{l}: closed {c}, quadrature {n}"
        );
    }
}

#[test]
fn closed_form_legendre_moments_match_quadrature() {
    assert_moments_match_quadrature("HG(0.7)", HenyeyGreenstein::new(0.7).unwrap());
    assert_moments_match_quadrature("HG(-0.4)", HenyeyGreenstein::new(-0.4).unwrap());
    assert_moments_match_quadrature("DHG", DoubleHenyeyGreenstein::new(0.8, -0.3, 0.6).unwrap());
    assert_moments_match_quadrature("Rayleigh", Rayleigh);
    assert_moments_match_quadrature("isotropic", Isotropic);
}

#[test]
fn legendre_series_reconstructs_the_phase_function() {
    // p(μ) = Σ (2l + 1)/(4π) χ_l P_l(μ): for HG(0.5) the series converges like 0.5^l.
    let hg = HenyeyGreenstein::new(0.5).unwrap();
    let chi = hg.legendre_moments(60);
    for mu in [-1.0, -0.3, 0.2, 0.9, 1.0] {
        let p = lucent_optics::integrate::legendre_polynomials(60, mu);
        let series: f64 = (0..=60)
            .map(|l| (2 * l + 1) as f64 / (4.0 * PI) * chi[l] * p[l])
            .sum();
        assert!(
            (series - hg.eval_cos(mu)).abs() < 1e-12 * hg.eval_cos(mu).max(1.0),
            "mu {mu}"
        );
    }
}

#[test]
fn henyey_greenstein_is_stable_at_the_extremes() {
    // Closed-form CDF, without cancellation for g > 0 (both terms under the root are
    // non-negative): P(μ) = (1 − g²)/(2g) · (1/s − 1/(1 + g)), s = √((1 − g)² + 2g(1 − μ)).
    // Backward lobes use the mirror symmetry P_g(μ) = 1 − P_{−g}(−μ).
    let forward_cdf = |g: f64, mu: f64| {
        let s = ((1.0 - g) * (1.0 - g) + 2.0 * g * (1.0 - mu)).sqrt();
        (1.0 - g * g) / (2.0 * g) * (1.0 / s - 1.0 / (1.0 + g))
    };
    let cdf = |g: f64, mu: f64| {
        if g > 0.0 {
            forward_cdf(g, mu)
        } else {
            1.0 - forward_cdf(-g, -mu)
        }
    };
    // Exact quantile in the stable variable δ = 1 − μ for a forward lobe:
    // δ = (1 − g)(1 − u)(s + 1 − g)/t, s = (1 − g²)/t, t = 1 − g + 2gu.
    let forward_quantile = |g: f64, u: f64| {
        let t = 1.0 - g + 2.0 * g * u;
        let s = (1.0 - g * g) / t;
        (1.0 - (1.0 - g) * (1.0 - u) * (s + 1.0 - g) / t).max(-1.0)
    };
    let quantile = |g: f64, u: f64| {
        if g > 0.0 {
            forward_quantile(g, u)
        } else {
            -forward_quantile(-g, 1.0 - u)
        }
    };
    for g in [-0.999_999, -0.99, -0.9, 0.5, 0.99, 0.999_999] {
        let hg = HenyeyGreenstein::new(g).unwrap();
        for k in 0..=100 {
            let u = k as f64 / 100.0;
            let mu = hg.sample_cos(u);
            assert!((-1.0..=1.0).contains(&mu));
            // A few ulps of 1 in μ: the best any f64 μ can do near the peak.
            assert!(
                (mu - quantile(g, u)).abs() < 1e-14,
                "g {g}, u {u}: μ {mu} vs {}",
                quantile(g, u)
            );
            if g.abs() <= 0.99 {
                // Away from extreme peaks, check in u too: dP/dμ ≤ 1e4 keeps this at 1e-9.
                assert!(
                    (cdf(g, mu) - u).abs() < 1e-9,
                    "g {g}, u {u}: CDF {}",
                    cdf(g, mu)
                );
            }
        }
        assert!(hg.eval_cos(1.0).is_finite() && hg.eval_cos(-1.0).is_finite());
    }
    // As g → 0 the sampler tends continuously to the isotropic 2u − 1 and the density to 1/(4π).
    for g in [1e-15, -1e-12, 1e-8] {
        let hg = HenyeyGreenstein::new(g).unwrap();
        for k in 0..=10 {
            let u = k as f64 / 10.0;
            assert!((hg.sample_cos(u) - (2.0 * u - 1.0)).abs() <= 4.0 * g.abs() + 1e-15);
        }
        assert!((hg.eval_cos(0.3) * 4.0 * PI - 1.0).abs() <= 4.0 * g.abs() + 1e-15);
    }
    assert!(HenyeyGreenstein::new(1.0).is_err());
    assert!(HenyeyGreenstein::new(-1.0).is_err());
    assert!(HenyeyGreenstein::new(f64::NAN).is_err());
    assert!(DoubleHenyeyGreenstein::new(0.5, 0.2, 1.5).is_err());
}

/// Numerically inverts the CDF built from `eval_cos` alone (not from the sampler) to find
/// the μ below which a fraction `q` of the scattered light lies.
fn quantile(phase: &impl PhaseFunction, q: f64) -> f64 {
    let (mut lo, mut hi) = (-1.0, 1.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        let mass = adaptive(|mu| 2.0 * PI * phase.eval_cos(mu), -1.0, mid, 1e-13, 0.0);
        if mass < q {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Upper critical value of χ² with `dof` degrees of freedom at one-sided significance
/// 1e-6 (z = 4.753), by the Wilson–Hilferty approximation (accurate to ~1% for dof ≥ 30).
fn chi2_critical(dof: f64) -> f64 {
    let z = 4.753;
    let c = 2.0 / (9.0 * dof);
    dof * (1.0 - c + z * c.sqrt()).powi(3)
}

#[test]
fn sampling_follows_the_density_chi_square() {
    // 25 equal-probability bins in μ (from the evaluated density) × 8 azimuth bins measured
    // in a frame the test builds itself: 200 cells of 1000 expected samples each. With a
    // fixed seed the test is deterministic; the 1e-6 significance keeps it meaningful (a
    // sampler off by 1% in g fails it by a wide margin).
    const MU_BINS: usize = 25;
    const PHI_BINS: usize = 8;
    const SAMPLES: usize = 200_000;
    let mut rng = Pcg64Mcg::seed_from_u64(0x5eed);
    for (name, phase) in all_phases() {
        let omega_in = DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalize();
        let edges: Vec<f64> = (1..MU_BINS)
            .map(|k| quantile(&phase, k as f64 / MU_BINS as f64))
            .collect();
        // An azimuth frame unrelated to the sampler's own.
        let e1 = if omega_in.x.abs() < 0.9 {
            DVec3::X
        } else {
            DVec3::Y
        }
        .reject_from(omega_in)
        .normalize();
        let e2 = omega_in.cross(e1);
        let mut counts = vec![0u32; MU_BINS * PHI_BINS];
        for _ in 0..SAMPLES {
            let s = phase.sample(omega_in, [rng.random(), rng.random()]);
            let mu = s.omega_out.dot(omega_in);
            let phi = s.omega_out.dot(e2).atan2(s.omega_out.dot(e1)) + PI;
            let i = edges.partition_point(|&e| e < mu);
            let j = ((phi / (2.0 * PI) * PHI_BINS as f64) as usize).min(PHI_BINS - 1);
            counts[i * PHI_BINS + j] += 1;
        }
        let expected = SAMPLES as f64 / (MU_BINS * PHI_BINS) as f64;
        let chi2: f64 = counts
            .iter()
            .map(|&c| (c as f64 - expected).powi(2) / expected)
            .sum();
        let critical = chi2_critical((MU_BINS * PHI_BINS - 1) as f64);
        assert!(chi2 < critical, "{name}: χ² = {chi2:.1} ≥ {critical:.1}");
    }
}

#[test]
fn chi_square_test_rejects_a_wrong_sampler() {
    // The test above must be able to fail: HG(0.3) sampled with HG(0.31)'s inverse CDF.
    struct Mismatched;
    impl PhaseFunction for Mismatched {
        fn eval_cos(&self, mu: f64) -> f64 {
            HenyeyGreenstein::new(0.3).unwrap().eval_cos(mu)
        }
        fn sample_cos(&self, u: f64) -> f64 {
            HenyeyGreenstein::new(0.31).unwrap().sample_cos(u)
        }
        fn mean_cosine(&self) -> f64 {
            0.3
        }
    }
    let mut rng = Pcg64Mcg::seed_from_u64(1);
    let edges: Vec<f64> = (1..25)
        .map(|k| quantile(&Mismatched, k as f64 / 25.0))
        .collect();
    let mut counts = [0u32; 25];
    for _ in 0..200_000 {
        let mu = Mismatched.sample_cos(rng.random());
        counts[edges.partition_point(|&e| e < mu)] += 1;
    }
    let chi2: f64 = counts
        .iter()
        .map(|&c| (c as f64 - 8000.0).powi(2) / 8000.0)
        .sum();
    assert!(
        chi2 > chi2_critical(24.0),
        "χ² = {chi2} should reject the wrong sampler"
    );
}

fn unit_vector() -> impl Strategy<Value = DVec3> {
    (-1.0f64..1.0, 0.0f64..(2.0 * PI)).prop_map(|(z, phi)| {
        let r = (1.0 - z * z).sqrt();
        DVec3::new(r * phi.cos(), r * phi.sin(), z)
    })
}

fn any_phase() -> impl Strategy<Value = Phase> {
    prop_oneof![
        Just(Phase::Isotropic),
        Just(Phase::Rayleigh),
        (-0.999f64..0.999).prop_map(|g| Phase::henyey_greenstein(g).unwrap()),
        (-0.99f64..0.99, -0.99f64..0.99, 0.0f64..1.0)
            .prop_map(|(a, b, w)| Phase::double_henyey_greenstein(a, b, w).unwrap()),
    ]
}

proptest! {
    #[test]
    fn sampled_pdf_equals_the_evaluated_phase_function(
        phase in any_phase(),
        omega_in in unit_vector(),
        u0 in 0.0f64..1.0,
        u1 in 0.0f64..1.0,
    ) {
        let s = phase.sample(omega_in, [u0, u1]);
        prop_assert!((s.omega_out.length() - 1.0).abs() < 1e-12);
        let evaluated = phase.eval(omega_in, s.omega_out);
        // Relative 1e-9: the direction is rebuilt from (μ, φ) and renormalised, which moves
        // μ by a few ulps; at the HG(0.999) peak dp/dμ / p ≈ 3/(2(1 − g)²)·… stays below 1e7.
        prop_assert!((s.pdf - evaluated).abs() <= 1e-9 * evaluated.max(1.0), "pdf {} vs eval {}", s.pdf, evaluated);
        prop_assert!((s.pdf - s.value).abs() <= f64::EPSILON * s.value);
    }
}
