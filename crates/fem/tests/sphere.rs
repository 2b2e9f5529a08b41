//! Q1 on the boundary-fitted ball against the closed-form Robin sphere (note 002 T7).

use lucent_fem::q1::Q1Multigrid;
use lucent_fem::solvers::Stopping;
use lucent_fem::sphere::BallMesh;
use lucent_optics::{Dielectric, DiffuseFresnel, DiffusionMedium, OpticalCoefficients};

/// Marble (σ_a = 0.0021, σ′_s = 2.19 /mm), R = 10 mm, Groenhuis A of η = 1.3, unit point
/// source at the centre: mean relative errors at r = R/4, R/2, R (over the vertices within
/// half a cell of each radius) and the relative L2 error over R/4 ≤ r ≤ R.
fn ball(cells: usize) -> ([f64; 3], f64) {
    let (sigma_a, sigma_s) = (0.0021, 2.19);
    let c = OpticalCoefficients::from_extinction_albedo(
        sigma_a + sigma_s,
        sigma_s / (sigma_a + sigma_s),
        0.0,
    )
    .unwrap();
    let m =
        DiffusionMedium::with_boundary(c, Dielectric::new(1.3).unwrap(), DiffuseFresnel::Groenhuis)
            .unwrap();
    let radius = 10.0;
    let analytic = m.sphere(radius).unwrap();
    let mesh = BallMesh::new(cells, radius).unwrap();
    let a = mesh.assemble(m.d(), sigma_a, m.boundary_factor()).unwrap();
    let mut b = vec![0.0; a.rows()];
    b[mesh.centre()] = 1.0;
    let mg = Q1Multigrid::for_lattice([cells; 3], a, 2);
    let mut x = vec![0.0; b.len()];
    let conv = mg
        .solve(
            &b,
            &mut x,
            &Stopping {
                relative_tolerance: 1e-10,
                max_iterations: 200,
                ..Stopping::default()
            },
        )
        .unwrap();
    assert!(conv.stop_reason.is_converged(), "{:?}", conv.stop_reason);
    let h = 2.0 * radius / cells as f64;
    let shell = |r: f64| {
        let (mut sum, mut count) = (0.0, 0);
        for (v, p) in x.iter().zip(&mesh.vertices) {
            if (p.length() - r).abs() < 0.5 * h {
                sum += v / analytic.fluence(p.length().clamp(1e-9, radius)).unwrap() - 1.0;
                count += 1;
            }
        }
        sum / count.max(1) as f64
    };
    let errors = [
        shell(radius / 4.0),
        shell(radius / 2.0),
        shell(radius - 1e-9),
    ];
    let (mut d, mut s) = (0.0, 0.0);
    for (v, p) in x.iter().zip(&mesh.vertices) {
        let r = p.length();
        if r >= radius / 4.0 {
            let e = analytic.fluence(r.min(radius)).unwrap();
            d += (v - e).powi(2);
            s += e * e;
        }
    }
    (errors, (d / s).sqrt())
}

#[test]
fn q1_on_the_ball_meets_t7_and_converges_at_second_order() {
    // The issue asks ≤ 2% at R/4, R/2, R and second order. Measured: at R/4, R/2, R
    // −0.58%, −0.21%, +0.59% (16 cells across), −0.13%, −0.06%, +0.14% (32), −0.032%,
    // −0.016%, +0.033% (64): a factor 4 per halving; L2 6.0e-2, 3.8e-3, 7.4e-4 (the
    // coarsest barely resolves the source). lucent-diffusion's cut cells on the same
    // sphere: 0.97% at 64³ (tests/analytic.rs).
    let results: Vec<([f64; 3], f64)> = [16, 32, 64].iter().map(|&n| ball(n)).collect();
    let (errors64, _) = results[2];
    assert!(errors64.iter().all(|e| e.abs() < 0.02), "{errors64:?}");
    let order = (results[0].1 / results[2].1).log2() / 2.0;
    assert!(order >= 1.7, "L2 order {order}: {results:?}");
    for w in results.windows(2) {
        let shell_order = (w[0].0[1] / w[1].0[1]).abs().log2();
        assert!(
            shell_order >= 1.7,
            "order at R/2: {shell_order}: {results:?}"
        );
    }
}
