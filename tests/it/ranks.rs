//! The registry's solvers on ranks, through both doors: the `ranks` parameter (in-process
//! ranks) and `SolveOptions::ranks` (what `mpirun -n N lucent solve` hands every process),
//! on scenes of every class the suite has (an embedded sphere with a Robin boundary, a
//! medium touching every face of a grid whose sides are not multiples of 8, RGB with a sky,
//! a box-filling medium lit from outside, a thin slab).
//!
//! - `ftcs-diffusion`, `jacobi-diffusion`, `ftcs-p1` and `convection-diffusion`: the serial
//!   bits (over z-slabs and over grids of boxes).
//! - `diffusion-mg`: the serial bits too (fluence, history and stop), on every rank count,
//!   over z-slabs and grids of boxes, and through both doors: its norms sum runs of eight
//!   cells exactly, as the serial solve's do.

use std::path::Path;
use std::sync::Arc;

use lucent::core::ranks::{Communicator, Threads};
use lucent::core::{ParamValue, Params, Problem, Solution, SolveError, SolveOptions};

const SCENES: [&str; 5] = [
    "suite/marble_sphere.toml",
    "suite/touching_faces.toml",
    "rgb_medium.toml",
    "box_filling.toml",
    "suite/slab.toml",
];

/// The scene with at most 20 cells along each axis (its `resolution` divided: the bits a
/// split must reproduce do not depend on the size, and 40³ RGB with 120 sweeps on five
/// decompositions took most of a minute per solver); the grids stay of every shape the
/// scenes have (13 × 11 × 19, 16 × 16 × 20, 4 × 4 × 16, cubes).
fn problem(scene: &str) -> Problem {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes");
    let path = root.join(scene);
    let dir = path.parent().unwrap().to_path_buf();
    let text = std::fs::read_to_string(&path).unwrap();
    let capped = match text.lines().find(|l| l.starts_with("resolution = [")) {
        Some(line) => {
            let dims: Vec<usize> = line
                .trim_start_matches("resolution = [")
                .split(']')
                .next()
                .unwrap()
                .split(',')
                .map(|v| v.trim().parse::<usize>().unwrap())
                .collect();
            // One factor for every axis, so that cubic cells stay cubic.
            let factor = dims.iter().max().unwrap().div_ceil(20);
            let dims: Vec<usize> = dims.iter().map(|n| (n / factor).max(2)).collect();
            text.replacen(line, &format!("resolution = {dims:?}"), 1)
        }
        None => text,
    };
    lucent::scene::Scene::parse(&capped, &path)
        .and_then(|s| s.build(&dir))
        .expect("the scene builds")
        .problem
}

fn params(ranks: i64) -> Params {
    let mut p = Params::default();
    p.0.insert("ranks".into(), ParamValue::Int(ranks));
    p
}

fn options(name: &str) -> SolveOptions {
    SolveOptions {
        // FTCS crawls: a fixed number of sweeps compares as well as convergence does.
        relative_tolerance: if name == "diffusion-mg" { 1e-9 } else { 1e-4 },
        max_iterations: if name == "diffusion-mg" { 100 } else { 120 },
        ..SolveOptions::default()
    }
}

fn solve(name: &str, problem: &Problem, ranks: i64) -> Solution {
    lucent::registry()
        .build(name, &params(ranks))
        .expect("a registered solver")
        .solve(problem, &options(name))
        .unwrap_or_else(|e| panic!("{name} on {ranks} ranks: {e}"))
}

/// Every process's solve under a world of `ranks`, as `mpirun` runs them: rank 0's
/// solution, after checking every rank got the same.
fn solve_as_processes(name: &str, problem: &Problem, ranks: usize) -> Solution {
    solve_as_processes_with(name, problem, ranks, &Params::default())
}

/// [`solve_as_processes`] with the solver built from `params`.
fn solve_as_processes_with(
    name: &str,
    problem: &Problem,
    ranks: usize,
    params: &Params,
) -> Solution {
    let solutions: Vec<Solution> = std::thread::scope(|scope| {
        let handles: Vec<_> = Threads::world(ranks)
            .into_iter()
            .map(|rank| {
                scope.spawn(move || {
                    let options = SolveOptions {
                        ranks: Some(Arc::new(rank)),
                        ..options(name)
                    };
                    lucent::registry()
                        .build(name, params)
                        .and_then(|s| s.solve(problem, &options))
                        .unwrap_or_else(|e| panic!("{name} as {ranks} processes: {e}"))
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for s in &solutions[1..] {
        assert_eq!(
            fluence_bits(s),
            fluence_bits(&solutions[0]),
            "{name}: ranks disagree"
        );
    }
    solutions.into_iter().next().unwrap()
}

fn fluence_bits(s: &Solution) -> Vec<u32> {
    s.fluence
        .iter()
        .flat_map(|g| g.data().iter().map(|v| v.to_bits()))
        .collect()
}

fn history_bits(s: &Solution) -> Vec<u64> {
    s.report
        .residual_history
        .iter()
        .map(|r| r.to_bits())
        .collect()
}

#[test]
fn steady_explicit_schemes_give_the_serial_bits_on_ranks() {
    for scene in SCENES {
        let problem = problem(scene);
        for name in ["ftcs-diffusion", "jacobi-diffusion"] {
            let serial = solve(name, &problem, 1);
            for (ranks, decomposition) in [(2, "slabs"), (3, "slabs"), (2, "boxes"), (4, "boxes")] {
                let mut p = params(ranks);
                p.0.insert(
                    "decomposition".into(),
                    ParamValue::Text(decomposition.into()),
                );
                let split = lucent::registry()
                    .build(name, &p)
                    .and_then(|s| s.solve(&problem, &options(name)))
                    .unwrap_or_else(|e| panic!("{name} on {ranks} {decomposition}: {e}"));
                let case = format!("{name} on {scene}, {ranks} ranks, {decomposition}");
                assert_eq!(fluence_bits(&split), fluence_bits(&serial), "{case}");
                assert_eq!(history_bits(&split), history_bits(&serial), "{case}");
                assert_eq!(split.report.stop_reason, serial.report.stop_reason);
            }
            let processes = solve_as_processes(name, &problem, 2);
            assert_eq!(
                fluence_bits(&processes),
                fluence_bits(&serial),
                "{name} on {scene} as processes"
            );
            assert_eq!(
                history_bits(&processes),
                history_bits(&serial),
                "{name} on {scene} as processes"
            );
        }
    }
}

#[test]
fn p1_gives_the_serial_bits_on_ranks() {
    // Point lights inside homogeneous media with vacuum edges (what `ftcs-p1` admits): a
    // 19 × 17 × 15 grid and a cubic 16³ one.
    for scene in ["suite/point_inside.toml", "suite/absorber_point.toml"] {
        let problem = problem(scene);
        let serial = solve("ftcs-p1", &problem, 1);
        for (ranks, decomposition) in [(2, "slabs"), (3, "slabs"), (4, "slabs"), (4, "boxes")] {
            let mut p = params(ranks);
            p.0.insert(
                "decomposition".into(),
                ParamValue::Text(decomposition.into()),
            );
            let split = lucent::registry()
                .build("ftcs-p1", &p)
                .and_then(|s| s.solve(&problem, &options("ftcs-p1")))
                .unwrap_or_else(|e| panic!("ftcs-p1 on {ranks} {decomposition}: {e}"));
            assert_eq!(
                fluence_bits(&split),
                fluence_bits(&serial),
                "{scene}, {ranks} ranks, {decomposition}"
            );
            assert_eq!(
                split.report.stop_reason, serial.report.stop_reason,
                "{scene}"
            );
            assert_eq!(split.report.iterations, serial.report.iterations, "{scene}");
            assert_eq!(history_bits(&split), history_bits(&serial), "{scene}");
        }
        assert!(!serial.report.residual_history.is_empty(), "{scene}");
        let processes = solve_as_processes("ftcs-p1", &problem, 3);
        assert_eq!(
            fluence_bits(&processes),
            fluence_bits(&serial),
            "{scene} as processes"
        );
    }
}

#[test]
fn multigrid_on_ranks_gives_the_serial_bits() {
    for scene in SCENES {
        let problem = problem(scene);
        let serial = solve("diffusion-mg", &problem, 1);
        assert!(serial.report.stop_reason.is_converged(), "{scene}");
        // The norms sum the same runs exactly on any number of ranks, so the history, the
        // stop and the fluence are the serial ones to the bit, on every rank count, over
        // slabs and boxes, and through both doors.
        for (ranks, decomposition) in [(2, "slabs"), (3, "slabs"), (4, "boxes")] {
            let mut p = params(ranks);
            p.0.insert(
                "decomposition".into(),
                ParamValue::Text(decomposition.into()),
            );
            let split = lucent::registry()
                .build("diffusion-mg", &p)
                .and_then(|s| s.solve(&problem, &options("diffusion-mg")))
                .unwrap_or_else(|e| panic!("diffusion-mg on {ranks} {decomposition}: {e}"));
            let (scene, ranks) = (format!("{scene} over {decomposition}"), ranks);
            assert_eq!(
                fluence_bits(&split),
                fluence_bits(&serial),
                "{scene}, {ranks}"
            );
            assert_eq!(
                history_bits(&split),
                history_bits(&serial),
                "{scene}, {ranks}"
            );
            assert_eq!(
                split.report.stop_reason, serial.report.stop_reason,
                "{scene}"
            );
        }
        let processes = solve_as_processes("diffusion-mg", &problem, 2);
        assert_eq!(fluence_bits(&processes), fluence_bits(&serial), "{scene}");
        assert_eq!(history_bits(&processes), history_bits(&serial), "{scene}");
        let mut boxes = Params::default();
        boxes
            .0
            .insert("decomposition".into(), ParamValue::Text("boxes".into()));
        let processes = solve_as_processes_with("diffusion-mg", &problem, 4, &boxes);
        assert_eq!(fluence_bits(&processes), fluence_bits(&serial), "{scene}");
        assert_eq!(history_bits(&processes), history_bits(&serial), "{scene}");
    }
}

/// `scene` with its (first) directional light turned to `direction`.
fn turned(scene: &str, direction: [f64; 3]) -> Problem {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes");
    let path = root.join(scene);
    let text = std::fs::read_to_string(&path).unwrap();
    let line = text
        .lines()
        .find(|l| l.starts_with("direction = "))
        .expect("a directional light");
    let text = text.replacen(line, &format!("direction = {direction:?}"), 1);
    lucent::scene::Scene::parse(&text, &path)
        .and_then(|s| s.build(path.parent().unwrap()))
        .expect("the scene builds")
        .problem
}

#[test]
fn the_absorption_march_gives_the_serial_bits_on_ranks() {
    // Lights along z (the pipelined wavefront), along x and y (planes in lock step), the
    // characteristic and the paper's model, with and without the scattering step (in the
    // isotropic media), on a
    // medium touching every face of a 13 × 11 × 19 grid, a cloud in 24³, a box-filling
    // medium in 16 × 16 × 20 and the 8 × 8 × 32 slab (RGB where the scene is).
    let scenes = [
        ("suite/touching_faces.toml", None),
        ("suite/touching_faces.toml", Some([0.9, -0.3, 0.2])),
        ("suite/touching_faces.toml", Some([-0.2, 0.8, -0.5])),
        ("suite/thin_smoke.toml", None),
        ("box_filling.toml", Some([-0.7, 0.3, 0.6])),
        ("suite/slab.toml", None),
    ];
    let variants: [&[(&str, ParamValue)]; 3] = [
        &[],
        &[("model", ParamValue::Text("paper".into()))],
        &[("scattering", ParamValue::Float(0.002))],
    ];
    let name = "convection-diffusion";
    for (scene, direction) in scenes {
        let problem = match direction {
            Some(d) => turned(scene, d),
            None => problem(scene),
        };
        // The scattering step takes isotropic media (box_filling, the slab).
        let isotropic = lucent::optics::PhaseFunction::mean_cosine(&problem.medium().phase) == 0.0;
        for variant in variants
            .iter()
            .filter(|v| isotropic || v.len() != 1 || v[0].0 != "scattering")
        {
            let with = |ranks: i64, decomposition: &str| {
                let mut p = params(ranks);
                p.0.insert(
                    "decomposition".into(),
                    ParamValue::Text(decomposition.into()),
                );
                for (key, value) in variant.iter() {
                    p.0.insert((*key).into(), value.clone());
                }
                lucent::registry()
                    .build(name, &p)
                    .unwrap()
                    .solve(&problem, &SolveOptions::default())
                    .unwrap_or_else(|e| panic!("{scene} {variant:?} on {ranks} ranks: {e}"))
            };
            let serial = with(1, "slabs");
            assert!(
                serial.fluence[0].data().iter().any(|&v| v > 0.0),
                "{scene}: some light arrives"
            );
            // Boxes: the grid of boxes that cuts least on each grid.
            for (ranks, decomposition) in [(2, "slabs"), (3, "slabs"), (3, "boxes"), (4, "boxes")] {
                let split = with(ranks, decomposition);
                assert_eq!(
                    fluence_bits(&split),
                    fluence_bits(&serial),
                    "{scene} {direction:?} {variant:?}, {ranks} ranks over {decomposition}"
                );
                assert_eq!(split.report.stop_reason, serial.report.stop_reason);
            }
        }
        // As processes (`SolveOptions::ranks`), the default model.
        let serial = solve(name, &problem, 1);
        let processes = solve_as_processes(name, &problem, 3);
        assert_eq!(
            fluence_bits(&processes),
            fluence_bits(&serial),
            "{scene} {direction:?} as processes"
        );
    }
}

#[test]
fn what_cannot_split_says_so() {
    let problem = problem("suite/slab.toml");
    let registry = lucent::registry();
    // A solver that runs in one process, handed two ranks.
    let world = Threads::world(2);
    let rank: Arc<dyn Communicator + Send + Sync> = Arc::new(world.into_iter().next().unwrap());
    let options = SolveOptions {
        ranks: Some(rank),
        ..SolveOptions::default()
    };
    for name in ["direct", "dom", "diffusion-cg"] {
        let e = registry
            .build(name, &Params::default())
            .unwrap()
            .solve(&problem, &options)
            .unwrap_err();
        assert!(
            matches!(&e, SolveError::Unsupported { feature, .. } if feature.contains("2 ranks")),
            "{name}: {e}"
        );
    }
    // Zhang & Ma's march splits its one-pass marches of distant lights only: the
    // conservative model is refused before it runs, a point light by the march.
    let mut conservative = Params::default();
    conservative
        .0
        .insert("model".into(), ParamValue::Text("conservative".into()));
    let e = registry
        .build("convection-diffusion", &conservative)
        .unwrap()
        .solve(&problem, &options)
        .unwrap_err();
    assert!(
        matches!(&e, SolveError::Unsupported { feature, .. } if feature.contains("2 ranks")),
        "{e}"
    );
    let e = registry
        .build("convection-diffusion", &params(2))
        .unwrap()
        .solve(&self::problem("point_light.toml"), &SolveOptions::default())
        .unwrap_err();
    assert!(
        matches!(&e, SolveError::Unsupported { feature, .. } if feature.contains("point light")),
        "{e}"
    );
    // Both doors at once, no ranks, too many ranks, and the multigrid under CG.
    let e = registry
        .build("diffusion-mg", &params(2))
        .unwrap()
        .solve(&problem, &options)
        .unwrap_err();
    assert!(
        matches!(&e, SolveError::InvalidParameter { name, .. } if name == "ranks"),
        "{e}"
    );
    let mut mgcg_boxes = Params::default();
    mgcg_boxes
        .0
        .insert("decomposition".into(), ParamValue::Text("boxes".into()));
    let e = registry.build("diffusion-mgcg", &mgcg_boxes).err().unwrap();
    assert!(
        matches!(&e, SolveError::InvalidParameter { name, .. } if name == "decomposition"),
        "{e}"
    );
    for (name, ranks) in [
        ("diffusion-mg", 0),
        ("jacobi-diffusion", 100_000),
        ("diffusion-mgcg", 2),
    ] {
        let e = registry.build(name, &params(ranks)).err().unwrap();
        assert!(
            matches!(&e, SolveError::InvalidParameter { name, .. } if name == "ranks"),
            "{e}"
        );
    }
    // More ranks than the (divided) slab's 16 layers.
    let e = registry
        .build("diffusion-mg", &params(17))
        .unwrap()
        .solve(&problem, &SolveOptions::default())
        .unwrap_err();
    assert!(e.to_string().contains("17 ranks for 16 z-layers"), "{e}");
    // A decomposition that is not one, and boxes that cannot be cut: more ranks than the
    // 4 × 4 × 16 slab can cut (251 is prime: 251 boxes along one axis, which none has).
    let mut cubes = params(2);
    cubes
        .0
        .insert("decomposition".into(), ParamValue::Text("cubes".into()));
    let e = registry.build("ftcs-diffusion", &cubes).err().unwrap();
    assert!(e.to_string().contains("decomposition"), "{e}");
    let mut boxes = params(251);
    boxes
        .0
        .insert("decomposition".into(), ParamValue::Text("boxes".into()));
    let e = registry
        .build("jacobi-diffusion", &boxes)
        .unwrap()
        .solve(&problem, &SolveOptions::default())
        .unwrap_err();
    assert!(e.to_string().contains("grid of boxes"), "{e}");
}
