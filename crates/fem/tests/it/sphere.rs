//! Q1 on the boundary-fitted ball against the closed-form Robin sphere (Mertens T7).

use lucent_core::Stopping;
use lucent_fem::q1::Q1Multigrid;
use lucent_fem::solvers::default_stopping;
use lucent_fem::sphere::StarMesh;
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
    let mesh = StarMesh::ball(cells, glam::DVec3::ZERO, radius).unwrap();
    let a = mesh.assemble(m.d(), sigma_a, m.boundary_factor()).unwrap();
    let mut b = vec![0.0; a.rows()];
    b[mesh.centre_node()] = 1.0;
    let mg = Q1Multigrid::for_lattice([cells; 3], a, 2);
    let mut x = vec![0.0; b.len()];
    let conv = mg
        .solve(
            &b,
            &mut x,
            &Stopping {
                relative_tolerance: 1e-10,
                max_iterations: 200,
                ..default_stopping()
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

/// The suite's marble sphere (Mertens T7, R = 10 mm, η = 1.3, partial-current A) as a
/// registry problem: the medium fills an n³ box of half-width 11 mm, the embedded SDF says
/// where the body is.
fn marble_problem(n: usize) -> lucent_core::Problem {
    use lucent_core::{Boundary, Field, Light, Medium, Problem, Spectrum};
    use lucent_grid::{Grid, GridGeometry};
    let geometry =
        GridGeometry::from_bounds([n; 3], glam::DVec3::splat(-11.0), glam::DVec3::splat(11.0))
            .unwrap();
    let sdf = Grid::from_fn(geometry, |p| (p.length() - 10.0) as f32);
    let medium = Medium {
        sigma_t: vec![Grid::filled(geometry, 2.1921)],
        albedo: vec![Field::Constant(0.999042)],
        phase: lucent_optics::Phase::Isotropic,
    };
    let light = Light::Point {
        position: glam::DVec3::ZERO,
        intensity: Spectrum::Grey(0.25 / std::f64::consts::PI),
    };
    Problem::new(
        geometry,
        medium,
        vec![light],
        Boundary::Robin { eta: 1.3 },
        Some(sdf),
    )
    .unwrap()
}

/// Relative L2 error against the analytic sphere over cell centres with 1.4 ≤ r ≤ 8.6 mm
/// (three transport mean free paths from source and surface, as the harness's reference).
fn marble_error(
    solution: &lucent_core::Solution,
    problem: &lucent_core::Problem,
    from: f64,
) -> f64 {
    let a = problem.boundary().robin_factor().unwrap();
    let c = OpticalCoefficients::from_extinction_albedo(2.1921, 0.999042, 0.0).unwrap();
    let analytic = DiffusionMedium::new(c, a).unwrap().sphere(10.0).unwrap();
    let g = problem.geometry();
    let (mut d, mut s) = (0.0, 0.0);
    for (cell, v) in solution.fluence(0).data().iter().enumerate() {
        let [i, j, k] = g.coords(cell);
        let r = g.cell_centre(i, j, k).length();
        if (from..=8.6).contains(&r) {
            let e = analytic.fluence(r).unwrap();
            d += (f64::from(*v) - e).powi(2);
            s += e * e;
        }
    }
    (d / s).sqrt()
}

#[test]
fn registry_fem_diffusion_meets_t7_on_an_embedded_sphere() {
    use lucent_core::{Params, SolveOptions, Solver};
    // Through the registry: the SDF's body is meshed with fitted elements (star-shaped
    // from its centroid) at the grid's spacing; cell values interpolate the nodal solution
    // at the cell centres. Measured relative L2 against T7 over 3 ≤ r ≤ 8.6 mm, fem versus
    // diffusion-mg's cut cells on the same problems: 16³ 2.3e-2 / 1.9e-2, 32³ 5.5e-3 /
    // 5.6e-3, 64³ 1.19e-3 / 1.38e-3 (orders 2.2 and 2.0). Nearer the point source
    // (from 1.4 mm, as the harness measures), trilinear interpolation of the 1/r field
    // costs the elements more at 32³: 2.0e-2 / 1.0e-2, and 3.1e-3 / 3.0e-3 at 64³.
    let options = SolveOptions {
        relative_tolerance: 1e-10,
        ..SolveOptions::default()
    };
    let mut far = Vec::new();
    for n in [32, 64] {
        let p = marble_problem(n);
        let fem = (lucent_fem::FemDiffusionSolver::ENTRY.build)(&Params::default())
            .unwrap()
            .solve(&p, &options)
            .unwrap();
        assert!(fem.report.stop_reason.is_converged(), "{:?}", fem.report);
        let mg = lucent_diffusion::DiffusionSolver::custom("diffusion-mg")
            .solve(&p, &options)
            .unwrap();
        let (e_fem, e_mg) = (marble_error(&fem, &p, 3.0), marble_error(&mg, &p, 3.0));
        // Within their discretisation errors: the two differ by no more than the sum of
        // their errors against the closed form (plus 10% for the cells' own error).
        let (mut d, mut s) = (0.0, 0.0);
        for (cell, (a, b)) in fem
            .fluence(0)
            .data()
            .iter()
            .zip(mg.fluence(0).data())
            .enumerate()
        {
            let [i, j, k] = p.geometry().coords(cell);
            if (3.0..=8.6).contains(&p.geometry().cell_centre(i, j, k).length()) {
                d += f64::from(a - b).powi(2);
                s += f64::from(*b).powi(2);
            }
        }
        let between = (d / s).sqrt();
        assert!(
            between < 1.1 * (e_fem + e_mg),
            "{n}³: {between} against {e_fem} + {e_mg}"
        );
        far.push(e_fem);
        if n == 64 {
            assert!(e_fem < 1.5e-3, "{e_fem}");
            let near = marble_error(&fem, &p, 1.4);
            assert!(near < 4e-3, "{near}");
        }
    }
    let order = (far[0] / far[1]).log2();
    assert!(order > 1.8, "order {order} from {far:?}");
}

#[test]
fn bodies_that_are_not_star_shaped_from_their_centre_are_refused() {
    use glam::DVec3;
    // A torus seen from its centre (outside the body) and two separate balls seen from
    // one of them: typed errors, not a tangled mesh.
    let torus = |p: DVec3| (DVec3::new(p.x, p.y, 0.0).length() - 0.6).hypot(p.z) - 0.2;
    assert!(StarMesh::from_sdf(8, DVec3::ZERO, torus, 3.0, 0.01).is_err());
    let balls =
        |p: DVec3| ((p - DVec3::X * 0.5).length() - 0.3).min((p + DVec3::X * 0.5).length() - 0.3);
    let err = StarMesh::from_sdf(8, DVec3::X * 0.5, balls, 3.0, 0.01).unwrap_err();
    assert!(err.to_string().contains("star-shaped"), "{err}");
    // A ball found by bisection lands on the closed-form radius.
    let mesh = StarMesh::from_sdf(8, DVec3::ZERO, |p| p.length() - 0.7, 3.0, 0.01).unwrap();
    let exact = StarMesh::ball(8, DVec3::ZERO, 0.7).unwrap();
    for (a, b) in mesh.vertices.iter().zip(&exact.vertices) {
        assert!((*a - *b).length() < 1e-8, "{a} {b}");
    }
}
