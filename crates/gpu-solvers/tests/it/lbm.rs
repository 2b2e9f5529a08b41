//! `gpu-lbm` against `lbm`: the lattice march step for step on every velocity set,
//! collision, absorption and wall, on grids whose sides are not multiples of 8 with
//! heterogeneous coefficients, sources and first moments; the energy books on the device;
//! the registry entries on heterogeneous scenes with lights outside and inside, grey and
//! RGB; and the refusals (blockwise scheduling, the sink's stability limit), on whatever
//! adapter exists (lavapipe in CI).

use glam::DVec3;
use lucent_core::{
    Boundary, Field, Light, Medium, ParamValue, Params, Problem, SolveError, SolveOptions,
    Spectrum, StopReason, Stopping,
};
use lucent_gpu::context_or_skip;
use lucent_gpu_solvers::{GpuSolver, lbm_march};
use lucent_grid::{Grid, GridGeometry};
use lucent_lbm::{
    Absorption, Blocks, Collision, LatticeProblem, LbmSolver, MarchSettings, Streaming, Velocities,
    Wall, march,
};
use lucent_optics::Phase;

/// A problem with coefficients drawn by a hash of the cell (as `lucent-lbm`'s own tests).
fn lattice_problem(
    dims: [usize; 3],
    collision: Collision,
    wall: Wall,
    seed: u64,
) -> LatticeProblem {
    let n: usize = dims.iter().product();
    let hash = |c: usize, salt: u64| {
        let mut x = (c as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ seed ^ salt;
        x ^= x >> 29;
        x = x.wrapping_mul(0xbf58_476d_1ce4_e5b9);
        x ^= x >> 32;
        (x >> 11) as f64 / (1u64 << 53) as f64
    };
    let (first, second): (Vec<f32>, Vec<f32>) = (0..n)
        .map(|c| match collision {
            Collision::Geist => {
                let kt = 0.1 + 0.8 * hash(c, 1);
                (kt as f32, (kt * (0.3 + 0.7 * hash(c, 2))) as f32)
            }
            _ => ((0.05 + 2.0 * hash(c, 1)) as f32, (0.2 * hash(c, 2)) as f32),
        })
        .unzip();
    LatticeProblem {
        dims,
        first,
        second,
        source: (0..n)
            .map(|c| {
                if hash(c, 3) > 0.6 {
                    hash(c, 4) as f32
                } else {
                    0.0
                }
            })
            .collect(),
        first_moment: (0..n)
            .map(|c| [0.1 * hash(c, 5) as f32, -0.05 * hash(c, 6) as f32, 0.02])
            .collect(),
        wall,
    }
}

fn settings(
    velocities: Velocities,
    collision: Collision,
    absorption: Absorption,
    steps: usize,
) -> MarchSettings {
    MarchSettings {
        velocities,
        collision,
        absorption,
        streaming: Streaming::TwoArrays,
        stopping: Stopping {
            relative_tolerance: 0.0,
            max_iterations: steps,
            ..Stopping::default()
        },
        blocks: None,
    }
}

/// max |a − b| / max |b|.
fn relative(a: &[f32], b: &[f32]) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, v| m.max(f64::from(v.abs())));
    let diff = a
        .iter()
        .zip(b)
        .fold(0.0f64, |m, (p, q)| m.max(f64::from((p - q).abs())));
    diff / scale.max(f64::MIN_POSITIVE)
}

#[test]
fn the_device_lattice_is_the_host_lattice_for_every_d3q7_scheme_and_wall() {
    the_device_lattice_is_the_host_lattice(Velocities::D3q7);
}

#[test]
fn the_device_lattice_is_the_host_lattice_for_every_d3q19_scheme_and_wall() {
    the_device_lattice_is_the_host_lattice(Velocities::D3q19);
}

/// The device's march is the host's, step by step, for every scheme of one velocity set
/// (the two sets are two tests, which run side by side).
fn the_device_lattice_is_the_host_lattice(velocities: Velocities) {
    let Some(gpu) = context_or_skip("the_device_lattice_is_the_host_lattice") else {
        return;
    };
    let walls = [
        Wall::Robin { a: 1.0657 },
        Wall::Robin { a: 2.6 },
        Wall::Dirichlet { value: 0.3 },
        Wall::Neumann { flux: 0.0 },
        Wall::Neumann { flux: -0.01 },
        Wall::Reflect { reflectance: 0.4 },
    ];
    // Every scheme (velocities × collision × absorption, 12) with two walls each, the
    // walls taken in turn so that each wall meets four schemes and both velocity sets: the
    // wall and the collision are separate parts of the kernel, so pairs cover what the full
    // product (72 cases, 8 640 device steps: 150 s on lavapipe) did, in a third of it.
    let (mut case, mut scheme) = match velocities {
        Velocities::D3q7 => (0u64, 0usize),
        Velocities::D3q19 => (12, 6),
    };
    for collision in [Collision::Trt, Collision::Bgk, Collision::Geist] {
        for absorption in [Absorption::True, Absorption::Thesis] {
            scheme += 1;
            for wall in [walls[scheme % 6], walls[(scheme + 3) % 6]] {
                case += 1;
                // Sides 13, 9, 11 (no multiple of 8, nor of the workgroup's 256 cells).
                let dims = [13, 9, 11];
                let problem = lattice_problem(dims, collision, wall, case);
                let s = settings(velocities, collision, absorption, 120);
                let host = march(&problem, &s).unwrap();
                let device = lbm_march(&gpu, &problem, &s, "gpu-lbm").unwrap();
                let what = format!("{velocities:?} {collision:?} {absorption:?} {wall:?}");
                // With no tolerance both run every step, unless the march reaches an
                // exact f32 fixed point (zero change: Geist's lattices with large κ_t
                // do within 120 steps), which each side may reach a few steps apart
                // or, with other roundings, circle one ulp away from.
                let fixed_point = matches!(host.stop_reason, StopReason::ConvergedAbsolute { .. });
                if !fixed_point {
                    assert_eq!(
                        device.steps, host.steps,
                        "{what}: {} vs {}",
                        device.stop_reason, host.stop_reason
                    );
                    assert_eq!(
                        std::mem::discriminant(&device.stop_reason),
                        std::mem::discriminant(&host.stop_reason),
                        "{what}"
                    );
                }
                // The same f32 arithmetic per cell; the device may contract a·b + c
                // into one rounding (fma) and divides to its own ≤ 2.5 ulp. The march
                // is a contraction (every collision a convex mix of the populations
                // plus sources), so per-step differences of a few ulp do not grow
                // beyond their sum over the memory of the march: 120 steps × 4 ulp
                // (2.4e-7 each) ≈ 3e-5 at worst; measured on lavapipe: at most 6.7e-7.
                let d = relative(&device.fluence, &host.fluence);
                assert!(d < 3e-5, "{what}: {d}");
                // The books: the device's per-workgroup f32 sums added in f64 on the
                // host, so rounding of ~8 ulp (pairwise over 256 cells) per step's
                // sums: conserved to 1e-5 of what moved.
                let e = device.bookkeeping.conservation_error();
                assert!(e < 1e-5, "{what}: conservation {e}");
                // The same books as the host's: totals over the same steps, or (at
                // a fixed point, reached at different steps) the rates per step.
                let (a, b) = (device.bookkeeping, host.bookkeeping);
                let compared = if fixed_point {
                    let [x, y] = [a.rates, b.rates];
                    [
                        (x[1], y[1], "absorbed per step", y[0]),
                        (x[2], y[2], "escaped per step", y[0]),
                        (a.held, b.held, "held", b.held),
                    ]
                } else {
                    let scale = b.emitted.max(b.absorbed + b.escaped.abs());
                    [
                        (a.absorbed, b.absorbed, "absorbed", scale),
                        (a.escaped, b.escaped, "escaped", scale),
                        (a.held, b.held, "held", scale),
                    ]
                };
                for (x, y, name, scale) in compared {
                    let scale = scale.abs().max(y.abs()).max(1e-300);
                    assert!((x - y).abs() < 3e-5 * scale, "{what}: {name} {x} vs {y}");
                }
            }
        }
    }
}

#[test]
fn blockwise_scheduling_and_sinks_beyond_the_limit_are_refused() {
    let Some(gpu) = context_or_skip("blockwise_scheduling_and_sinks_beyond_the_limit") else {
        return;
    };
    let problem = lattice_problem([6, 5, 7], Collision::Trt, Wall::Robin { a: 2.0 }, 3);
    let mut s = settings(Velocities::D3q7, Collision::Trt, Absorption::True, 10);
    s.blocks = Some(Blocks {
        slabs: 2,
        steps_per_visit: 1,
    });
    match lbm_march(&gpu, &problem, &s, "gpu-lbm") {
        Err(SolveError::InvalidParameter { name, .. }) => assert_eq!(name, "block_slabs"),
        other => panic!("blockwise: {other:?}"),
    }
    s.blocks = None;
    let mut sink = problem.clone();
    sink.second[17] = 1.5;
    match lbm_march(&gpu, &sink, &s, "gpu-lbm") {
        Err(SolveError::Unstable { limit, .. }) => assert_eq!(limit, 1.0),
        other => panic!("sink: {other:?}"),
    }
    let mut nan = problem;
    nan.source[3] = f32::NAN;
    assert!(matches!(
        lbm_march(&gpu, &nan, &s, "gpu-lbm"),
        Err(SolveError::InvalidParameter { .. })
    ));
}

fn registry() -> lucent_core::Registry {
    let mut r = lucent_core::Registry::with_core_solvers();
    r.register(LbmSolver::ENTRY);
    for e in GpuSolver::ENTRIES {
        r.register(e);
    }
    r
}

/// Through the registry: the same stopping rule on both sides, so both stop within the
/// tolerance of the same steady state, on heterogeneous media touching the box, with a
/// light outside (first-collision sources and first moments), a point light inside, grey
/// and RGB, both lattices.
#[test]
fn gpu_lbm_matches_lbm_through_the_registry() {
    let Some(_) = context_or_skip("gpu_lbm_matches_lbm_through_the_registry") else {
        return;
    };
    for (dims, lattice, rgb, boundary) in [
        ([19, 14, 10], "d3q7", false, Boundary::Vacuum),
        ([12, 17, 9], "d3q19", true, Boundary::Robin { eta: 1.4 }),
    ] {
        let geometry = GridGeometry::new(dims, DVec3::splat(0.1), DVec3::ZERO).unwrap();
        let (lo, hi) = geometry.bounds();
        let channels = if rgb { 3 } else { 1 };
        let sigma_t: Vec<Grid> = (0..channels)
            .map(|c| {
                Grid::from_fn(geometry, |x| {
                    let u = (x - lo) / (hi - lo);
                    let blob = (-6.0 * (u - DVec3::new(0.5, 0.4, 0.6)).length_squared()).exp();
                    ((4.0 + 2.0 * c as f64) * (0.3 + blob)) as f32
                })
            })
            .collect();
        let problem = Problem::new(
            geometry,
            Medium {
                albedo: vec![Field::Constant(0.9); channels],
                sigma_t,
                phase: Phase::henyey_greenstein(0.3).unwrap(),
            },
            vec![
                Light::Directional {
                    direction: DVec3::new(0.3, -0.4, 0.85).normalize(),
                    irradiance: Spectrum::Grey(1.0),
                },
                Light::Point {
                    position: 0.5 * (lo + hi) + DVec3::new(0.03, -0.02, 0.01),
                    intensity: Spectrum::Grey(0.2),
                },
            ],
            boundary,
            None,
        )
        .unwrap();
        let params = Params(
            [("lattice".to_string(), ParamValue::Text(lattice.into()))]
                .into_iter()
                .collect(),
        );
        let options = SolveOptions {
            relative_tolerance: 1e-6,
            max_iterations: 20_000,
            ..SolveOptions::default()
        };
        let solve = |name: &str| {
            registry()
                .build(name, &params)
                .unwrap()
                .solve(&problem, &options)
                .unwrap_or_else(|e| panic!("{name}: {e}"))
        };
        let (cpu, gpu) = (solve("lbm"), solve("gpu-lbm"));
        assert!(
            matches!(gpu.report.stop_reason, StopReason::ConvergedRelative { .. }),
            "{lattice}: {}",
            gpu.report.stop_reason
        );
        for c in 0..channels {
            // Both stop where the step's change and the energy imbalance fall below 1e-6;
            // the slowest mode contracts by ρ ≈ 1 − 1e-2 per step on these boxes (a few
            // diffusion lengths across), so each is within 1e-6/(1 − ρ) ≈ 1e-4 of the
            // steady state, and the device may finish a batch beyond the stopping step
            // (nearer). 5e-4 holds the two, plus f32 rounding.
            let d = relative(gpu.fluence(c).data(), cpu.fluence(c).data());
            assert!(d < 5e-4, "{lattice} channel {c}: {d}");
        }
    }
}
