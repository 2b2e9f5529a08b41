//! lucent-diffusion against closed-form diffusion solutions (Mertens T7, T8, T9 of docs/reference-cases.md).

use glam::{DVec2, DVec3};
use lucent_core::Stopping;
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, DiffusionProblem, DiffusionSolution, Discretisation,
    Method, Side, Sources, solve,
};
use lucent_grid::GridGeometry;
use lucent_optics::materials::MeasuredMaterial;
use lucent_optics::{Dielectric, DiffuseFresnel, DiffusionMedium, OpticalCoefficients};

/// A medium (σ_a, σ′_s) behind a surface with the Groenhuis A of η = 1.3, as T7–T9 use.
fn medium(sigma_a: f64, sigma_s_reduced: f64) -> DiffusionMedium {
    let sigma_t = sigma_a + sigma_s_reduced;
    let c = OpticalCoefficients::from_extinction_albedo(sigma_t, sigma_s_reduced / sigma_t, 0.0)
        .unwrap();
    DiffusionMedium::with_boundary(c, Dielectric::new(1.3).unwrap(), DiffuseFresnel::Groenhuis)
        .unwrap()
}

fn tight() -> Stopping {
    Stopping {
        relative_tolerance: 1e-10,
        ..Stopping::default()
    }
}

struct Sphere {
    grid: GridGeometry,
    centre: DVec3,
    radius: f64,
    problem: DiffusionProblem,
    sources: Sources,
    solution: DiffusionSolution,
}

/// The T7 sphere of radius R on an n³ grid a little larger than it, centred off the grid's
/// nodes and faces, with a unit point source at its centre.
fn sphere(n: usize, radius: f64, m: &DiffusionMedium) -> Sphere {
    let half = 1.05 * radius;
    let grid = GridGeometry::from_bounds([n; 3], DVec3::splat(-half), DVec3::splat(half)).unwrap();
    let centre = DVec3::new(0.0173, -0.0091, 0.0057) * radius;
    let cells = CellGeometry::from_sdf(
        grid,
        |p| (p - centre).length() - radius,
        Discretisation::EmbeddedBoundary,
    )
    .unwrap();
    let cells_n = grid.voxel_count();
    let c = m.coefficients();
    let problem = DiffusionProblem::new(
        cells,
        vec![m.d() as f32; cells_n],
        vec![c.sigma_a() as f32; cells_n],
        Boundaries::uniform(Condition::Robin {
            a: m.boundary_factor(),
        }),
    )
    .unwrap();
    let sources = Sources {
        points: vec![(centre, 1.0)],
        ..Sources::default()
    };
    let solution = solve(&problem, &sources, Method::default(), &tight()).unwrap();
    assert!(solution.convergence.stop_reason.is_converged());
    Sphere {
        grid,
        centre,
        radius,
        problem,
        sources,
        solution,
    }
}

impl Sphere {
    /// Largest relative error of whole cells whose centres lie within h/2 of radius r.
    fn shell_error(&self, analytic: &lucent_optics::analytic::RobinSphere, r: f64) -> f64 {
        let h = self.grid.spacing().x;
        let kappa = self.problem.cells().volume_fraction();
        (0..self.grid.voxel_count())
            .filter_map(|c| {
                let [i, j, k] = self.grid.coords(c);
                let rc = (self.grid.cell_centre(i, j, k) - self.centre).length();
                ((rc - r).abs() < 0.5 * h && kappa[c] >= 1.0)
                    .then(|| (self.solution.fluence[c] / analytic.fluence(rc).unwrap() - 1.0).abs())
            })
            .fold(0.0, f64::max)
    }

    /// Relative L2 error over whole cells with R/4 ≤ r ≤ R.
    fn l2_error(&self, analytic: &lucent_optics::analytic::RobinSphere) -> f64 {
        let kappa = self.problem.cells().volume_fraction();
        let (mut e2, mut r2) = (0.0, 0.0);
        for c in 0..self.grid.voxel_count() {
            let [i, j, k] = self.grid.coords(c);
            let r = (self.grid.cell_centre(i, j, k) - self.centre).length();
            if r >= 0.25 * self.radius && r <= self.radius && kappa[c] >= 1.0 {
                let exact = analytic.fluence(r).unwrap();
                e2 += (self.solution.fluence[c] - exact).powi(2);
                r2 += exact * exact;
            }
        }
        (e2 / r2).sqrt()
    }

    /// The surface fluence from the Robin relation, per patch: (area-weighted mean relative
    /// error, fraction of the area off by more than 5%).
    fn surface_error(&self, exact: f64) -> (f64, f64) {
        let values = self
            .problem
            .surface_fluence(&self.sources, &self.solution.fluence);
        let (mut mean, mut bad, mut total) = (0.0, 0.0, 0.0);
        for (p, v) in self.problem.cells().patches().iter().zip(values) {
            assert_eq!(p.side, Side::Surface);
            let e = v / exact - 1.0;
            mean += p.area * e;
            total += p.area;
            if e.abs() > 0.05 {
                bad += p.area;
            }
        }
        (mean / total, bad / total)
    }
}

#[test]
fn t7_spheres_at_64_cubed() {
    // Mertens T7: marble red R = 10 and 5, skin1 red R = 5, Groenhuis A (η = 1.3). The
    // issue asks ≤ 2% at R/4, R/2 and R at 64³; measured at most 0.97% (the worst cell
    // within h/2 of R/4 or R/2, marble R = 10 at R/4) and 0.05% (area-weighted surface
    // fluence; the facets' area off by more than 5% is 5e-7 of the total). Energy balance to
    // 1e-6, and the escaped fraction within 0.1% of T7's (measured 0.02% at worst).
    let marble = medium(0.0021, 2.19);
    let skin1 = MeasuredMaterial::by_name("skin1").unwrap();
    let skin1 = DiffusionMedium::with_boundary(
        skin1.channel(0, 0.0).unwrap(),
        Dielectric::new(1.3).unwrap(),
        DiffuseFresnel::Groenhuis,
    )
    .unwrap();
    for (m, radius, printed) in [
        (
            marble,
            10.0,
            [1.455077e-1, 4.716763e-2, 3.214529e-3, 0.776210],
        ),
        (
            marble,
            5.0,
            [3.209014e-1, 1.150398e-1, 1.537528e-2, 0.928164],
        ),
        (
            skin1,
            5.0,
            [1.052657e-1, 3.769908e-2, 9.912175e-3, 0.598371],
        ),
    ] {
        let analytic = m.sphere(radius).unwrap();
        // The closed form is T7's (checked to its digits in lucent-optics).
        for (r, value) in [(radius / 4.0, printed[0]), (radius / 2.0, printed[1])] {
            assert!((analytic.fluence(r).unwrap() / value - 1.0).abs() < 1e-6);
        }
        let s = sphere(64, radius, &m);
        for r in [radius / 4.0, radius / 2.0] {
            let e = s.shell_error(&analytic, r);
            assert!(e < 0.02, "R = {radius}: error {e} at r = {r}");
        }
        let (mean, bad) = s.surface_error(printed[2]);
        assert!(mean.abs() < 0.02, "R = {radius}: surface error {mean}");
        assert!(bad < 0.01, "R = {radius}: {bad} of the surface off by > 5%");
        let b = s.solution.balance;
        assert!(b.relative_imbalance() < 1e-6, "{b:?}");
        let escaped = b.escaped_surface + b.escaped_box;
        assert!(b.escaped_box == 0.0);
        assert!(
            (escaped / printed[3] - 1.0).abs() < 1e-3,
            "escaped {escaped}, T7 {}",
            printed[3]
        );
    }
}

#[test]
fn sphere_converges_at_second_order() {
    // Relative L2 error over R/4 ≤ r ≤ R, marble R = 10: measured 5.8e-3, 1.9e-3, 4.6e-4
    // at 32³, 64³, 128³ (orders 1.6 and 2.0; 1.8 overall). The issue asks ≥ 1.7 from 32³
    // to 128³; each step must at least be 1.5.
    let m = medium(0.0021, 2.19);
    let analytic = m.sphere(10.0).unwrap();
    let errors: Vec<f64> = [32, 64, 128]
        .iter()
        .map(|&n| sphere(n, 10.0, &m).l2_error(&analytic))
        .collect();
    let order = |a: f64, b: f64, ratio: f64| (a / b).ln() / ratio.ln();
    assert!(order(errors[0], errors[2], 4.0) >= 1.7, "{errors:?}");
    assert!(order(errors[0], errors[1], 2.0) >= 1.5, "{errors:?}");
    assert!(order(errors[1], errors[2], 2.0) >= 1.5, "{errors:?}");
}

#[test]
fn tilted_half_space_with_a_plane_source() {
    // Mertens T9 with the surface tilted off the grid's axes: medium {n·x < c}, a plane
    // source of unit strength at depth z′ = 1 mm parallel to it (spread over one cell
    // height), Robin condition on the surface, reflecting box faces far from the compared
    // column. σ_a = 0.1, σ′_s = 0.9 per mm: diffusion length 1.8 mm, so the box's sides,
    // 8 mm from the column, perturb it by about n_x e^{−8/1.8} ≈ 0.2%. The issue asks
    // ≤ 2%; measured 0.4% at worst over the column's whole cells down to 5 mm (excluding
    // those within two cells of the source, and 5 mm above the floor, whose image would
    // add e^{−2·5/1.8} = 0.4%), and the surface fluence and exitance within 0.1%.
    let m = medium(0.1, 0.9);
    let z_source = 1.0;
    let n = DVec3::new(0.15, 0.1, 1.0).normalize();
    // Cells 0.5 mm across and 0.25 mm high: depth runs nearly along z.
    let grid =
        GridGeometry::from_bounds([64, 64, 64], DVec3::ZERO, DVec3::new(32.0, 32.0, 16.0)).unwrap();
    let h = grid.spacing().z;
    let mid = DVec3::new(16.0, 16.0, 10.0);
    let c = n.dot(mid);
    let depth = |p: DVec3| c - n.dot(p);
    let cells =
        CellGeometry::from_sdf(grid, |p| -depth(p), Discretisation::EmbeddedBoundary).unwrap();
    let cells_n = grid.voxel_count();
    let mut boundaries = Boundaries::uniform(Condition::Neumann { flux: 0.0 });
    boundaries.surface = Condition::Robin {
        a: m.boundary_factor(),
    };
    let problem = DiffusionProblem::new(
        cells,
        vec![m.d() as f32; cells_n],
        vec![0.1; cells_n],
        boundaries,
    )
    .unwrap();
    // The plane source as a hat of half-width h in the vertical distance u to the plane:
    // samples of such hats a cell apart sum to one in every column, so each column gets
    // exactly the plane's strength over its footprint (h²/n_z). In depth the hat is
    // n_z h wide, and the reference below is the analytic solution for that hat.
    let hat = |u: f64| (1.0 - u.abs() / h).max(0.0);
    let volumetric = (0..cells_n)
        .map(|cell| {
            let [i, j, k] = grid.coords(cell);
            let u = (depth(grid.cell_centre(i, j, k)) - z_source) / n.z;
            (hat(u) / (n.z * h)) as f32
        })
        .collect();
    // φ for the smeared source: ∫ hat(s/n_z)/(n_z h) φ_{z′+s}(z) ds by a 256-point
    // midpoint rule over the hat's support (smooth pieces, error ~1e-6).
    let reference = |z: f64| {
        let w = n.z * h;
        let steps = 256;
        (0..steps)
            .map(|q| {
                let s = -w + (q as f64 + 0.5) * 2.0 * w / steps as f64;
                let source = m.half_space(z_source + s).unwrap();
                hat(s / n.z) / w * source.fluence(z).unwrap() * 2.0 * w / steps as f64
            })
            .sum::<f64>()
    };
    let sources = Sources {
        volumetric,
        ..Sources::default()
    };
    let solution = solve(&problem, &sources, Method::default(), &tight()).unwrap();
    assert!(solution.convergence.stop_reason.is_converged());
    let kappa = problem.cells().volume_fraction();
    let in_column = |p: DVec3| (p.x - mid.x).abs() < 8.0 && (p.y - mid.y).abs() < 8.0;
    let mut worst: f64 = 0.0;
    for cell in 0..cells_n {
        let [i, j, k] = grid.coords(cell);
        let p = grid.cell_centre(i, j, k);
        let z = depth(p);
        // Down to 5 mm deep and 5 mm above the box's (reflecting) floor.
        if in_column(p)
            && kappa[cell] >= 1.0
            && z < 5.0
            && p.z > 5.0
            && (z - z_source).abs() > 2.0 * h
        {
            let e = solution.fluence[cell] / reference(z) - 1.0;
            worst = worst.max(e.abs());
        }
    }
    assert!(worst < 0.02, "worst error {worst}");
    let surface = problem.surface_fluence(&sources, &solution.fluence);
    let fluxes = problem.patch_fluxes(&sources, &solution.fluence);
    let exact = reference(0.0);
    let (mut phi, mut exitance, mut area) = (0.0, 0.0, 0.0);
    for ((p, v), f) in problem.cells().patches().iter().zip(surface).zip(fluxes) {
        let [i, j, k] = grid.coords(p.cell);
        if p.side == Side::Surface && in_column(grid.cell_centre(i, j, k)) {
            phi += v * p.area;
            exitance += f;
            area += p.area;
        }
    }
    assert!((phi / area / exact - 1.0).abs() < 0.01, "{}", phi / area);
    let exact_exitance = exact / (2.0 * m.boundary_factor());
    assert!(
        (exitance / area / exact_exitance - 1.0).abs() < 0.01,
        "exitance {} vs {exact_exitance}",
        exitance / area
    );
}

/// The 2D disc of Mertens T8 (the thesis's Figure 4.1): a 100 × 100 (or finer) grid over a
/// 10 mm square, one cell thick with reflecting faces, a circle of radius 4.37 mm and a
/// unit source between the four middle cells. Returns the worst relative error of the cells
/// that carry the boundary, against the analytic solution at their centres.
fn disc_boundary_error(n: usize, discretisation: Discretisation) -> (f64, f64) {
    let m = medium(0.0021, 2.19);
    let radius = 4.37;
    let analytic = m.disc(radius).unwrap();
    let h = 10.0 / n as f64;
    let grid =
        GridGeometry::from_bounds([n, n, 1], DVec3::ZERO, DVec3::new(10.0, 10.0, h)).unwrap();
    let centre = DVec2::new(5.0, 5.0);
    let cells = CellGeometry::from_sdf(
        grid,
        |p| (DVec2::new(p.x, p.y) - centre).length() - radius,
        discretisation,
    )
    .unwrap();
    let count = grid.voxel_count();
    let mut boundaries = Boundaries::uniform(Condition::Robin {
        a: m.boundary_factor(),
    });
    boundaries.faces[4] = Condition::Neumann { flux: 0.0 };
    boundaries.faces[5] = Condition::Neumann { flux: 0.0 };
    let problem = DiffusionProblem::new(
        cells,
        vec![m.d() as f32; count],
        vec![0.0021; count],
        boundaries,
    )
    .unwrap();
    // Unit power per unit length: h per cell layer.
    let sources = Sources {
        points: vec![(DVec3::new(5.0, 5.0, 0.5 * h), h)],
        ..Sources::default()
    };
    let solution = solve(&problem, &sources, Method::default(), &tight()).unwrap();
    assert!(solution.convergence.stop_reason.is_converged());
    let mut worst: f64 = 0.0;
    for p in problem.cells().patches() {
        if p.side != Side::Surface {
            continue;
        }
        let [i, j, k] = grid.coords(p.cell);
        let q = grid.cell_centre(i, j, k);
        let r = (DVec2::new(q.x, q.y) - centre).length();
        let e = solution.fluence[p.cell] / analytic.fluence(r).unwrap() - 1.0;
        if e.abs() > worst.abs() {
            worst = e;
        }
    }
    let escaped = solution.balance.escaped_surface / h;
    (worst, escaped / analytic.escaped_fraction() - 1.0)
}

#[test]
fn figure_4_1_staircase_fails_where_the_embedded_boundary_holds() {
    // Mertens T8: the staircase's boundary cells are off by 13–27% and do not
    // converge (its rim is 8R long instead of 2πR, so it leaks too much); the embedded
    // boundary's must be within 2% at h = R/350. Measured: staircase −25% (N = 100) and
    // −26% (N = 400), leaking 0.5% too much at both; embedded boundary −0.24% already at
    // N = 100 (h = R/44) and −0.04% at N = 400, leakage within 2e-5.
    let (stair, stair_escape) = disc_boundary_error(100, Discretisation::Staircase);
    assert!(stair.abs() >= 0.10, "staircase boundary error {stair}");
    assert!(stair_escape > 0.004, "staircase leakage {stair_escape}");
    let (stair_fine, _) = disc_boundary_error(400, Discretisation::Staircase);
    assert!(
        stair_fine.abs() >= 0.10,
        "the staircase does not converge: {stair_fine}"
    );
    for n in [100, 400] {
        let (eb, eb_escape) = disc_boundary_error(n, Discretisation::EmbeddedBoundary);
        assert!(eb.abs() <= 0.02, "N = {n}: embedded boundary error {eb}");
        assert!(eb_escape.abs() < 1e-3, "N = {n}: leakage error {eb_escape}");
    }
}
