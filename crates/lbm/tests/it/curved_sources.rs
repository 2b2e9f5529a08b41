//! First-collision sources along curved rays (Bernabei ch. 4; `lucent_core::Uncollided::
//! curved`): the lights outside a medium of graded refractive index reach the lattice and
//! `diffusion-mg` through the same driver path as `direct-refractive`'s rays.
//!
//! - With straight rays the curved path's midpoint rule gives the straight path's
//!   conservative face rule to its O((σ_t h)²) error, cell by cell away from the kinks of
//!   τ, and its total to first order in h.
//! - Without scattering, `lbm` and `diffusion-mg` return `direct-refractive`'s fluence,
//!   averaged over the cells (they refused a graded index before).
//! - With scattering, `lbm` and `diffusion-mg` agree on a graded problem as they do on a
//!   straight one, and the lens changes their answer (the index is not ignored).

use glam::DVec3;
use lucent_core::{
    Boundary, DirectRefractiveSolver, Field, Light, Medium, Params, Problem, RefractiveIndex,
    SolveOptions, Solver, Spectrum, Uncollided,
};
use lucent_diffusion::DiffusionSolver;
use lucent_grid::{Grid, GridGeometry};
use lucent_lbm::LbmSolver;
use lucent_optics::Phase;
use lucent_optics::eikonal::GaussianBump;

const N: usize = 20;

/// A blob of medium in the unit box under a sun slightly off the z axis, with or without a
/// Gaussian lens of index (η = 1 + 0.05 e^{−|x − c|²/0.15²}, c = (0.5, 0.5, 0.3)).
fn problem(albedo: f32, lens: bool) -> Problem {
    problem_on(N, albedo, lens)
}

fn problem_on(n: usize, albedo: f32, lens: bool) -> Problem {
    let geometry = GridGeometry::new([n, n, n], DVec3::splat(1.0 / n as f64), DVec3::ZERO).unwrap();
    let sigma_t = Grid::from_fn(geometry, |x| {
        (1.0 + 4.0 * (-6.0 * (x - DVec3::new(0.5, 0.5, 0.55)).length_squared()).exp()) as f32
    });
    let problem = Problem::new(
        geometry,
        Medium {
            sigma_t: vec![sigma_t],
            albedo: vec![Field::Constant(albedo)],
            phase: Phase::henyey_greenstein(0.5).unwrap(),
        },
        vec![Light::Directional {
            direction: DVec3::new(0.1, -0.05, 1.0).normalize(),
            irradiance: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
        None,
    )
    .unwrap();
    if lens {
        problem
            .with_refractive_index(RefractiveIndex::Gaussian(GaussianBump {
                eta0: 1.0,
                amplitude: 0.05,
                centre: DVec3::new(0.5, 0.5, 0.3),
                width: 0.15,
            }))
            .unwrap()
    } else {
        problem
    }
}

/// max |a − b| / max |b|.
fn relative(a: &[f32], b: &[f32]) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, v| m.max(f64::from(v.abs())));
    let diff = a
        .iter()
        .zip(b)
        .fold(0.0f64, |m, (p, q)| m.max(f64::from((p - q).abs())));
    diff / scale
}

#[test]
fn straight_rays_give_the_face_rules_collisions_to_second_order() {
    let p = problem(0.9, false);
    let options = SolveOptions::default();
    let straight = Uncollided::new(&p, &options).unwrap();
    let curved = Uncollided::curved(&p, &options).unwrap();
    let (a, b) = (&curved.cells[0][0], &straight.cells[0][0]);
    let largest = b.collided.iter().fold(0.0f64, |m, v| m.max(*v));
    let w = DVec3::new(0.1, -0.05, 1.0).normalize();
    for (cell, (x, y)) in a.collided.iter().zip(&b.collided).enumerate() {
        // The direction of travel is the beam's.
        assert!((a.directed[cell] - w * *x).length() < 1e-9 * largest);
        // The midpoint rule against the cell average of σ_t E e^{−τ}: the error is
        // h²/24 Σ_a ∂²_a(σ_t E T)/(σ_t E T) per cell, with σ_t h ≤ 0.25 and the blob's
        // σ_t varying over 0.4 of the box: (0.25)²/24 · 3 ≈ 8e-3 of the cell's value at
        // worst. Not in the cells the plane through the box's upstream edges crosses
        // (x < 0.1 z and y > 1 − 0.05 z, the two cells next to the faces the tilted beam
        // also enters by): τ has a kink there, where the midpoint rule is first order.
        let (i, j) = (cell % N, (cell / N) % N);
        if i >= 2 && j + 2 <= N {
            let e = (x - y).abs() / y;
            assert!(e < 1e-2, "cell {cell}: {x} vs {y}");
        }
    }
    // Both books close: emitted is the straight rays' (the same power enters the box).
    assert_eq!(a.emitted, b.emitted);
    let total: f64 = a.collided.iter().sum();
    assert!((a.emitted - total - a.escaped).abs() < 1e-12 * a.emitted);
    // In total the curved path is first order in h: the cells next to the faces the
    // tilted beam enters by sideways hold a kink of τ (measured: 0.75 % of the collided
    // power at 20³, all of it in those layers); halving h halves it.
    let gap = |n: usize| {
        let p = problem_on(n, 0.9, false);
        let straight = Uncollided::new(&p, &options).unwrap();
        let curved = Uncollided::curved(&p, &options).unwrap();
        let sum = |u: &Uncollided| u.cells[0][0].collided.iter().sum::<f64>();
        (sum(&curved) - sum(&straight)).abs() / sum(&straight)
    };
    let (coarse, fine) = (gap(N), gap(2 * N));
    assert!(coarse < 1.5e-2, "{coarse}");
    assert!(
        coarse / fine > 1.6,
        "first order: {coarse} at {N}, {fine} at {}",
        2 * N
    );
}

#[test]
fn without_scattering_lbm_and_diffusion_return_the_curved_rays_fluence() {
    let p = problem(0.0, true);
    let options = SolveOptions::default();
    let reference = DirectRefractiveSolver::default()
        .solve(&p, &options)
        .unwrap();
    let average: Vec<f32> = Uncollided::curved(&p, &options)
        .unwrap()
        .fluence(0)
        .iter()
        .map(|&v| v as f32)
        .collect();
    let solvers: [Box<dyn Solver>; 2] = [
        Box::new(LbmSolver::new(Default::default())),
        (DiffusionSolver::MULTIGRID.build)(&Params::default()).unwrap(),
    ];
    for solver in solvers {
        let solution = solver
            .solve(&p, &options)
            .unwrap_or_else(|e| panic!("{}: {e}", solver.name()));
        // No scattering: the solve adds nothing to the uncollided light, which is the
        // curved path's cell average (f32 storage: 1e-6) ...
        let d = relative(solution.fluence(0).data(), &average);
        assert!(d < 1e-5, "{}: {d}", solver.name());
        // ... that is direct-refractive's centre value times the chord factor
        // 2 sinh(x/2)/x ≈ 1 + x²/24, x = σ_t h/max|ω_a| ≤ 5 · 0.05/0.99: within 2.7e-3.
        let d = relative(solution.fluence(0).data(), reference.fluence(0).data());
        assert!(d < 2.7e-3, "{}: {d}", solver.name());
    }
}

#[test]
fn with_scattering_lbm_and_diffusion_agree_and_the_lens_matters() {
    let options = SolveOptions::default();
    let lensed = problem(0.9, true);
    let plain = problem(0.9, false);
    let lbm = LbmSolver::new(Default::default());
    let mg = (DiffusionSolver::MULTIGRID.build)(&Params::default()).unwrap();
    let a = lbm.solve(&lensed, &options).unwrap();
    let b = mg.solve(&lensed, &options).unwrap();
    // The same diffusion equation, D, sources and Robin walls, second order in h on both
    // sides: on the suite's straight-ray scenes of this size they agree to 0.3-0.9 %
    // (tolerances.toml); the curved sources change nothing in that.
    let d = relative(a.fluence(0).data(), b.fluence(0).data());
    assert!(d < 1e-2, "lbm vs diffusion-mg: {d}");
    // The lens concentrates the beam behind it: the answer moves by several per cent.
    let c = mg.solve(&plain, &options).unwrap();
    let moved = relative(b.fluence(0).data(), c.fluence(0).data());
    assert!(moved > 2e-2, "the lens moved the fluence by only {moved}");
}
