//! Murray's finite-element system: exact stencils, Jacobi's divergence, Krylov and direct
//! solves.

use std::f64::consts::PI;

use lucent_core::StopReason;
use lucent_core::Stopping;
use lucent_fem::murray::{Mesh, MurraySystem};
use lucent_fem::solvers::{bicgstab, default_stopping, gauss_seidel, gmres, jacobi, lu_solve};
use lucent_fem::{Dense, LinearOperator};
use proptest::prelude::*;

fn bounded(n: usize) -> Mesh {
    Mesh {
        nodes: [n; 3],
        spacing: 1.0,
        periodic: false,
    }
}

#[test]
fn assembled_stencils_are_the_notes_exact_values() {
    // Interior vertex of a 5³ mesh, unit spacing: δ = [⅙, ⅔, ⅙]^⊗3 (8/27, 2/27, 1/54,
    // 1/216), β_x = [−½, 0, ½] ⊗ [⅙, ⅔, ⅙]² (±2/9, ±1/18, ±1/72), γ = diag(4π, 4π/3 ×3),
    // α_{0a} = α_{a0} = 4π/3 e_a, all to 1e-12.
    let kt = 0.7;
    let s = MurraySystem::assemble(bounded(5), kt).unwrap();
    let a = &s.matrix;
    let m = |d: i32| if d == 0 { 2.0 / 3.0 } else { 1.0 / 6.0 };
    let b = |d: i32| 0.5 * f64::from(d);
    let centre = 2 + 5 * (2 + 5 * 2);
    let g = [4.0 * PI, 4.0 * PI / 3.0, 4.0 * PI / 3.0, 4.0 * PI / 3.0];
    let entry = |row: usize, col: usize| a.get(row, col).copied().unwrap_or(0.0);
    for dz in -1..=1 {
        for dy in -1..=1 {
            for dx in -1..=1 {
                let other = (centre as i32 + dx + 5 * dy + 25 * dz) as usize;
                let delta = m(dx) * m(dy) * m(dz);
                for (i, gi) in g.iter().enumerate() {
                    let v = entry(4 * centre + i, 4 * other + i) / (kt * gi);
                    assert!(
                        (v - delta).abs() < 1e-12,
                        "δ at {dx},{dy},{dz}: {v} vs {delta}"
                    );
                }
                let beta = [
                    b(dx) * m(dy) * m(dz),
                    m(dx) * b(dy) * m(dz),
                    m(dx) * m(dy) * b(dz),
                ];
                for axis in 0..3 {
                    for (row, col) in [(0, axis + 1), (axis + 1, 0)] {
                        let v = entry(4 * centre + row, 4 * other + col) / (4.0 * PI / 3.0);
                        assert!(
                            (v - beta[axis]).abs() < 1e-12,
                            "β_{axis} at {dx},{dy},{dz}: {v}"
                        );
                    }
                }
                // No coupling between different flux components (α_{ab} = 0 for a, b ≥ 1).
                assert_eq!(entry(4 * centre + 1, 4 * other + 2), 0.0);
            }
        }
    }
    // Spot values named in the note.
    assert!((m(0).powi(3) - 8.0 / 27.0).abs() < 1e-15);
    assert!((b(1) * m(1) * m(1) - 1.0 / 72.0).abs() < 1e-15);
    assert!((b(1) * m(0) * m(0) - 2.0 / 9.0).abs() < 1e-15);
}

#[test]
fn jacobi_spectral_radius_is_at_least_nineteen_eighths() {
    // Jacobi's spectral radius (Fourier analysis, docs/reference-cases.md): 2.375 = 19/8 for K_tΔ ≥ 10, 2.483 at 1, 20.39 at
    // 0.1. Measured by power iteration on a periodic mesh (16³ for the small K_t, whose
    // worst Fourier mode an 8³ mesh misses: 19.87 there).
    for (kt, nodes, expected, tolerance) in [
        (10.0, 8, 2.375, 0.01),
        (100.0, 8, 2.375, 0.01),
        (1.0, 8, 2.483, 0.01),
        (0.1, 16, 20.39, 0.01),
    ] {
        let mesh = Mesh {
            nodes: [nodes; 3],
            spacing: 1.0,
            periodic: true,
        };
        let rho = MurraySystem::assemble(mesh, kt)
            .unwrap()
            .jacobi_spectral_radius(400);
        assert!(
            (rho / expected - 1.0).abs() < tolerance,
            "K_tΔ = {kt}: {rho}"
        );
    }
}

#[test]
fn jacobi_diverges_and_is_stopped_while_krylov_and_lu_solve_it() {
    // A point source in a bounded 6³ mesh (864 unknowns), K_tΔ = 1. Jacobi: DivergedGrowth.
    // GMRES(60) and BiCGSTAB: 1e-10 with their residual histories; both equal the direct
    // LU solution to 1e-8.
    let s = MurraySystem::assemble(bounded(6), 1.0).unwrap();
    let b = s.point_source([3, 3, 3], 1.0);
    let n = b.len();
    let mut x = vec![0.0; n];
    let j = jacobi(&s.matrix, &b, &mut x, &default_stopping()).unwrap();
    assert!(
        matches!(j.stop_reason, StopReason::DivergedGrowth { .. }),
        "{:?}",
        j.stop_reason
    );
    assert!(x.iter().all(|v| v.is_finite()));
    let exact = lu_solve(&s.matrix, &b).unwrap();
    let norm = exact.iter().map(|v| v * v).sum::<f64>().sqrt();
    let stopping = Stopping {
        relative_tolerance: 1e-10,
        max_iterations: 20_000,
        ..default_stopping()
    };
    let mut xg = vec![0.0; n];
    let g = gmres(&s.matrix, &b, &mut xg, 60, &stopping).unwrap();
    assert!(g.stop_reason.is_converged(), "GMRES: {:?}", g.stop_reason);
    assert!(
        g.residuals.len() > 2
            && g.residuals
                .windows(2)
                .all(|w| w[1] <= w[0] * (1.0 + 1e-9) || w[1] < 1e-9)
    );
    let mut xb = vec![0.0; n];
    let c = bicgstab(&s.matrix, &b, &mut xb, &stopping).unwrap();
    assert!(
        c.stop_reason.is_converged(),
        "BiCGSTAB: {:?}",
        c.stop_reason
    );
    for (name, x) in [("gmres", &xg), ("bicgstab", &xb)] {
        let e = x
            .iter()
            .zip(&exact)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt()
            / norm;
        assert!(e < 1e-8, "{name}: {e}");
    }
    // Solved exactly, the Galerkin system still is not a sound transport solution: the
    // fluence alternates in sign along the axis through the source (measured 28.7, −4.4,
    // 24.8): central (Galerkin) differencing of a first-order operator decouples odd and
    // even vertices, as Murray's P1 FTCS does: a sound FE transport solver needs a
    // stabilised formulation.
    let phi = s.fluence(&exact);
    let at = |i: usize| phi[i + 6 * (3 + 6 * 3)];
    assert!(
        at(4) < 0.0 && at(3) > 0.0 && at(5) > 0.0,
        "{} {} {}",
        at(3),
        at(4),
        at(5)
    );
}

fn random_matrix(n: usize, seed: u64, symmetric: bool) -> Dense {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let raw: Vec<f64> = (0..n * n).map(|_| next()).collect();
    let mut data = vec![0.0; n * n];
    if symmetric {
        // Bᵀ B + I: symmetric positive definite.
        for i in 0..n {
            for j in 0..n {
                data[i * n + j] = (0..n).map(|k| raw[k * n + i] * raw[k * n + j]).sum::<f64>()
                    + if i == j { 1.0 } else { 0.0 };
            }
        }
    } else {
        // Strictly diagonally dominant, non-symmetric.
        data.copy_from_slice(&raw);
        for i in 0..n {
            let off: f64 = (0..n)
                .filter(|&j| j != i)
                .map(|j| raw[i * n + j].abs())
                .sum();
            data[i * n + i] = off + 0.5 + raw[i * n + i].abs();
        }
    }
    Dense { n, data }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn krylov_matches_the_direct_solve(n in 3usize..40, seed in 0u64..10_000, symmetric in any::<bool>()) {
        // Random SPD and non-symmetric diagonally dominant systems: GMRES and BiCGSTAB to
        // 1e-12 agree with LU to 1e-8 (condition numbers here stay below ~1e3).
        let a = random_matrix(n, seed, symmetric);
        let b: Vec<f64> = (0..n).map(|i| ((i * 7 + 3) % 11) as f64 - 5.0).collect();
        let exact = lu_solve(&a, &b).unwrap();
        let scale = exact.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
        let stopping = Stopping { relative_tolerance: 1e-12, max_iterations: 2000, ..default_stopping() };
        let mut x = vec![0.0; n];
        let g = gmres(&a, &b, &mut x, 20, &stopping).unwrap();
        prop_assert!(g.stop_reason.is_converged(), "{:?}", g.stop_reason);
        let e = x.iter().zip(&exact).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt() / scale;
        prop_assert!(e < 1e-8, "gmres {e}");
        let mut x = vec![0.0; n];
        let c = bicgstab(&a, &b, &mut x, &stopping).unwrap();
        prop_assert!(c.stop_reason.is_converged(), "{:?}", c.stop_reason);
        let e = x.iter().zip(&exact).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt() / scale;
        prop_assert!(e < 1e-8, "bicgstab {e}");
        // And the operator's product is what the dense rows say.
        let mut y = vec![0.0; n];
        a.apply(&exact, &mut y);
        let r = y.iter().zip(&b).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        prop_assert!(r < 1e-9 * (1.0 + b.iter().fold(0.0f64, |m, v| m.max(v.abs()))));
    }
}

#[test]
fn gauss_seidel_converges_on_a_diagonally_dominant_fe_mass_system() {
    // Gauss–Seidel is a baseline too: on the absorption-only block (streaming off, i.e. the
    // SPD mass matrix times K_t) it converges, where Jacobi on the same matrix does not
    // (spectral radius 19/8).
    let mesh = bounded(6);
    let s = MurraySystem::assemble(mesh, 1.0).unwrap();
    // Keep only the (0, 0) blocks: K_t 4π δ.
    let n = mesh.len();
    let mut t = sprs::TriMat::new((n, n));
    for (v, (r, c)) in s.matrix.iter() {
        if r % 4 == 0 && c % 4 == 0 {
            t.add_triplet(r / 4, c / 4, *v);
        }
    }
    let mass: sprs::CsMat<f64> = t.to_csr();
    let b: Vec<f64> = (0..n).map(|i| 1.0 + (i % 3) as f64).collect();
    let stopping = Stopping {
        relative_tolerance: 1e-10,
        max_iterations: 5000,
        ..default_stopping()
    };
    let mut x = vec![0.0; n];
    let gs = gauss_seidel(&mass, &b, &mut x, &stopping).unwrap();
    assert!(gs.stop_reason.is_converged(), "{:?}", gs.stop_reason);
    let mut y = vec![0.0; n];
    let j = jacobi(&mass, &b, &mut y, &stopping).unwrap();
    assert!(
        matches!(j.stop_reason, StopReason::DivergedGrowth { .. }),
        "{:?}",
        j.stop_reason
    );
}

#[test]
fn row_assembly_is_the_element_triplets_matrix() {
    // The row-by-row assembly (every vertex gathers its elements' blocks) against the
    // element triplets summed into CSR: the same structure, every entry equal to rounding
    // (sums of at most 8 element terms in another order: 1e-14 of the largest entry), on
    // bounded meshes of even and odd sides (not cubes), periodic ones, with and without
    // extinction.
    let meshes = [
        Mesh {
            nodes: [4, 5, 3],
            spacing: 0.5,
            periodic: false,
        },
        Mesh {
            nodes: [7, 6, 9],
            spacing: 1.25,
            periodic: false,
        },
        Mesh {
            nodes: [3, 4, 5],
            spacing: 1.0,
            periodic: true,
        },
        Mesh {
            nodes: [6, 6, 6],
            spacing: 0.1,
            periodic: true,
        },
    ];
    for mesh in meshes {
        for sigma_t in [0.0, 0.7, 12.0] {
            let rows = MurraySystem::assemble(mesh, sigma_t).unwrap().matrix;
            let elements = MurraySystem::assemble_by_elements(mesh, sigma_t)
                .unwrap()
                .matrix;
            let what = format!("{mesh:?}, K_t = {sigma_t}");
            assert_eq!(rows.shape(), elements.shape(), "{what}");
            assert_eq!(
                rows.indptr().raw_storage(),
                elements.indptr().raw_storage(),
                "{what}"
            );
            assert_eq!(rows.indices(), elements.indices(), "{what}");
            let scale = elements.data().iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (a, b) in rows.data().iter().zip(elements.data()) {
                assert!((a - b).abs() <= 1e-14 * scale, "{what}: {a} vs {b}");
            }
        }
    }
}

#[test]
fn gmres_stops_inside_a_restart_cycle() {
    // Ctrl-C raised during the 5th matrix-vector product of a GMRES(30) cycle: the cycle
    // ends at the steps it has (its iterate is GMRES's over them) and the solve says
    // Interrupted after 5 iterations, not after the 30 of a whole cycle (a cycle at 24³
    // took 0.3-0.5 s, too long for a stop that must come within a second under load).
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
    struct Raising<'a> {
        a: &'a Dense,
        products: AtomicUsize,
        cancel: Arc<AtomicBool>,
    }
    impl LinearOperator for Raising<'_> {
        fn dim(&self) -> usize {
            self.a.dim()
        }
        fn apply(&self, x: &[f64], y: &mut [f64]) {
            // The first product is the initial residual's; the 6th the 5th Arnoldi step's.
            if self.products.fetch_add(1, Ordering::Relaxed) + 1 == 6 {
                self.cancel.store(true, Ordering::Relaxed);
            }
            self.a.apply(x, y);
        }
    }
    let a = random_matrix(60, 7, false);
    let b: Vec<f64> = (0..60).map(|i| (i as f64 * 0.37).sin()).collect();
    let cancel = Arc::new(AtomicBool::new(false));
    let op = Raising {
        a: &a,
        products: AtomicUsize::new(0),
        cancel: cancel.clone(),
    };
    let stopping = Stopping {
        relative_tolerance: 1e-300,
        max_iterations: 1000,
        cancel: Some(cancel),
        ..default_stopping()
    };
    let mut x = vec![0.0; 60];
    let c = gmres(&op, &b, &mut x, 30, &stopping).unwrap();
    assert!(
        matches!(c.stop_reason, StopReason::Interrupted { .. }),
        "{:?}",
        c.stop_reason
    );
    assert_eq!(c.residuals.len() - 1, 5, "{:?}", c.residuals);
    // The iterate is the 5-step GMRES iterate: its residual is the one reported.
    let mut r = vec![0.0; 60];
    a.apply(&x, &mut r);
    let true_residual = r
        .iter()
        .zip(&b)
        .map(|(r, b)| (b - r).powi(2))
        .sum::<f64>()
        .sqrt()
        / b.iter().map(|b| b * b).sum::<f64>().sqrt();
    assert!(
        (true_residual - c.residuals[5]).abs() <= 1e-12,
        "{true_residual} vs {:?}",
        c.residuals
    );
    assert!(c.residuals[5] < c.residuals[0]);
}
