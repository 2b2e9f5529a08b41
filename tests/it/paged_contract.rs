//! What every registered solver that pages (`Solver::pages`) promises: on a paged medium it
//! gives the bits of its in-memory solve of the same medium, across classes of scenes —
//! grids whose sides are no multiple of the bricks (bricks of 4 and 8), media touching the
//! box or floating inside it, suns from several sides, point and spot lights inside and
//! outside the box, the sky, grey and RGB extinction, a uniform medium lit from inside —
//! with the pool a small part of the
//! bricks. A solver that pages but cannot take a scene says `Unsupported` on both paths
//! alike (and each solver must take at least one scene). Solvers that do not page refuse
//! with `Unsupported` naming themselves.

use std::sync::Arc;

use glam::DVec3;
use lucent::core::{
    Boundary, CellMedium, Field, Light, Medium, PagedProblem, ParamValue, Params, Problem,
    SolveError, SolveOptions, Spectrum,
};
use lucent::grid::{BrickLayout, Grid, GridGeometry};
use lucent::optics::Phase;
use lucent::paging::{Eviction, FileStore, Pager, PagerOptions};

type CellFn = Box<dyn Fn(DVec3) -> f32 + Sync>;

/// One scene class: a grid, a medium given cell by cell, lights.
struct Class {
    what: &'static str,
    geometry: GridGeometry,
    sigma_t: Vec<CellFn>,
    albedo: CellFn,
    phase: Phase,
    lights: Vec<Light>,
}

fn classes() -> Vec<Class> {
    let unit = |dims: [usize; 3]| {
        let h = 1.0 / dims.into_iter().max().unwrap() as f64;
        GridGeometry::new(dims, DVec3::splat(h), DVec3::new(-0.2, 0.1, 0.0)).unwrap()
    };
    vec![
        Class {
            what: "a cloud touching three faces, a low sun",
            geometry: unit([13, 10, 11]),
            sigma_t: vec![Box::new(|p: DVec3| {
                let r = (p - DVec3::new(0.0, 0.2, 0.1)).length();
                if r > 0.6 {
                    0.0
                } else {
                    (12.0 * (0.7 - r) * (1.0 + 0.4 * (11.0 * p.y).sin())) as f32
                }
            })],
            albedo: Box::new(|_| 0.85),
            phase: Phase::henyey_greenstein(0.3).unwrap(),
            lights: vec![Light::Directional {
                direction: DVec3::new(0.8, -0.3, -0.5).normalize(),
                irradiance: Spectrum::Grey(2.0),
            }],
        },
        Class {
            what: "a floating blob, RGB extinction, a sun from below and a point light inside",
            geometry: unit([9, 17, 6]),
            sigma_t: [3.0f64, 6.0, 12.0]
                .into_iter()
                .map(|s| {
                    Box::new(move |p: DVec3| {
                        (s * (-30.0 * (p - DVec3::new(0.25, 0.55, 0.15)).length_squared()).exp())
                            as f32
                    }) as CellFn
                })
                .collect(),
            albedo: Box::new(|p: DVec3| (0.5 + 0.4 * (5.0 * p.x).cos().abs()) as f32),
            phase: Phase::henyey_greenstein(0.3).unwrap(),
            lights: vec![
                Light::Directional {
                    direction: DVec3::new(0.1, 0.2, 1.0).normalize(),
                    irradiance: Spectrum::Rgb([1.0, 0.5, 0.25]),
                },
                Light::Point {
                    position: DVec3::new(0.1, 0.5, 0.2),
                    intensity: Spectrum::Grey(0.3),
                },
            ],
        },
        Class {
            what: "a slab filling the box's bottom, a spot from outside and the sky",
            geometry: unit([16, 7, 12]),
            sigma_t: vec![Box::new(|p: DVec3| if p.z < 0.3 { 5.0 } else { 0.0 })],
            albedo: Box::new(|_| 0.6),
            phase: Phase::henyey_greenstein(0.3).unwrap(),
            lights: vec![
                Light::Spot {
                    position: DVec3::new(0.4, 0.2, 1.5),
                    direction: DVec3::NEG_Z,
                    intensity: Spectrum::Grey(4.0),
                    inner_angle: 0.3,
                    outer_angle: 0.6,
                },
                Light::Sky {
                    radiance: Spectrum::Grey(0.5),
                },
            ],
        },
        Class {
            what: "a uniform medium filling the box, isotropic, point lights inside only",
            geometry: unit([11, 6, 9]),
            sigma_t: vec![Box::new(|_| 7.0)],
            albedo: Box::new(|_| 0.7),
            phase: Phase::Isotropic,
            lights: vec![
                Light::Point {
                    position: DVec3::new(0.25, 0.35, 0.3),
                    intensity: Spectrum::Rgb([1.0, 0.6, 0.3]),
                },
                Light::Point {
                    position: DVec3::new(0.65, 0.2, 0.55),
                    intensity: Spectrum::Grey(0.4),
                },
            ],
        },
    ]
}

/// Cheap parameters; `mc` takes the bricks as its majorant blocks, as it does out of core.
fn params_for(name: &str, brick: usize) -> Params {
    let mut p = Params::default();
    if name == "mc" {
        p.0.insert("particles".into(), ParamValue::Int(300));
        p.0.insert("batches".into(), ParamValue::Int(3));
        p.0.insert("majorant_cells".into(), ParamValue::Int(brick as i64));
    }
    p
}

/// The class's medium paged in bricks of `brick`³ cells, with a pool of an eighth of the
/// bricks of the medium and a dozen result fields (at least the pins of running batches).
fn paged_problem(class: &Class, brick: usize) -> PagedProblem {
    let g = class.geometry;
    let layout = BrickLayout::new(g.dims(), brick).unwrap();
    let len = layout.stored_len();
    let slots = (layout.count() * 16 / 8).max(32) as u64;
    let pager = Arc::new(
        Pager::new(
            Box::new(FileStore::create().unwrap()),
            0,
            len,
            1,
            PagerOptions {
                budget_bytes: slots * 4 * len as u64,
                eviction: Eviction::Nru,
                fill: 0.0,
            },
        )
        .unwrap(),
    );
    PagedProblem::from_fn(
        pager,
        g,
        brick,
        CellMedium {
            sigma_t: class.sigma_t.iter().map(|f| f.as_ref()).collect(),
            albedo: vec![class.albedo.as_ref()],
            phase: class.phase,
        },
        class.lights.clone(),
        Boundary::Vacuum,
    )
    .unwrap()
}

fn bits(grid: &Grid) -> Vec<u32> {
    grid.data().iter().map(|v| v.to_bits()).collect()
}

#[test]
fn paging_solvers_give_their_in_memory_bits_on_every_scene_class() {
    let registry = lucent::registry();
    let mut paging = Vec::new();
    for entry in registry.entries() {
        let name = entry.name;
        let solver = registry.build(name, &Params::default()).unwrap();
        if !solver.pages() {
            // It says so, by name, before any work.
            let class = &classes()[0];
            let paged = paged_problem(class, 4);
            match solver.solve_paged(&paged, &SolveOptions::default()) {
                Err(SolveError::Unsupported { solver, .. }) => assert_eq!(solver, name),
                other => panic!("{name} does not page but answered {other:?}"),
            }
            continue;
        }
        paging.push(name);
        let mut taken = 0;
        for class in classes() {
            for brick in [4, 8] {
                let solver = registry.build(name, &params_for(name, brick)).unwrap();
                let what = format!("{name} on {} with bricks of {brick}", class.what);
                let g = class.geometry;
                let medium = Medium {
                    sigma_t: class.sigma_t.iter().map(|f| Grid::from_fn(g, f)).collect(),
                    albedo: vec![Field::Grid(Grid::from_fn(g, &class.albedo))],
                    phase: class.phase,
                };
                let dense =
                    Problem::new(g, medium, class.lights.clone(), Boundary::Vacuum, None).unwrap();
                let paged = paged_problem(&class, brick);
                // Iterative solvers stop at a limit (the steady FTCS schemes take
                // thousands of steps here); the bits of the same iterations are compared.
                let options = SolveOptions {
                    max_iterations: 300,
                    ..SolveOptions::default()
                };
                let out_of_core = match solver.solve_paged(&paged, &options) {
                    Err(SolveError::Unsupported { feature, .. }) => {
                        // Refused out of core: fine where the scene is beyond what the
                        // paged path takes, never silently different.
                        eprintln!("{what}: not out of core ({feature})");
                        continue;
                    }
                    other => other.unwrap_or_else(|e| panic!("{what}: {e}")),
                };
                let memory = solver
                    .solve(&dense, &options)
                    .unwrap_or_else(|e| panic!("{what}: in memory: {e}"));
                assert_eq!(out_of_core.fluence.len(), memory.fluence.len(), "{what}");
                for (c, (p, m)) in out_of_core.fluence.iter().zip(&memory.fluence).enumerate() {
                    assert!(
                        bits(&p.to_grid().unwrap()) == bits(m),
                        "{what}: fluence channel {c}"
                    );
                }
                assert!(
                    memory
                        .fluence
                        .iter()
                        .any(|f| f.data().iter().any(|&v| v > 0.0)),
                    "{what}: nothing lit"
                );
                assert_eq!(
                    out_of_core.report.stop_reason, memory.report.stop_reason,
                    "{what}"
                );
                taken += 1;
            }
        }
        assert!(taken > 0, "{name} pages but took no scene class");
    }
    // The solvers the issue asks to page, at least.
    for name in [
        "direct",
        "convection-diffusion",
        "mc",
        "ftcs-diffusion",
        "jacobi-diffusion",
        "ftcs-p1",
        "ftcs-ordinates",
    ] {
        assert!(paging.contains(&name), "{name} does not page: {paging:?}");
    }
}

/// A budget that cannot do is refused before the medium is built, naming the smallest
/// that would (checked for every solver that pages and each class of light it takes): at
/// that budget the scene is admitted, and 5 % below it refused. (A 384³ cloud was once
/// built for 41 s and then refused.)
#[test]
fn a_budget_that_cannot_do_is_refused_before_building_with_the_smallest_that_would() {
    let scenes = [
        // A sun and the sky on a cloud; a point light inside a blob.
        "[volume]\nkind = \"cloud\"\nresolution = [72, 60, 66]\nbounds = [[-1, -1, -1], [1, 1, 1]]\nseed = 3\n[medium]\ndensity = 20.0\nalbedo = 0.9\n[[lights]]\nkind = \"directional\"\ndirection = [0.3, 0.2, -0.93]\nirradiance = 1.0\n[[lights]]\nkind = \"sky\"\nradiance = 0.1\n",
        "[volume]\nkind = \"blob\"\nresolution = [61, 70, 64]\nbounds = [[0, 0, 0], [1, 1, 1]]\ncentre = [0.5, 0.5, 0.5]\nsigma = 0.2\n[medium]\ndensity = 8.0\nalbedo = 0.8\n[[lights]]\nkind = \"point\"\nposition = [0.4, 0.5, 0.55]\nintensity = 1.0\n",
    ];
    let registry = lucent::registry();
    let mut checked = 0;
    for text in scenes {
        let text = format!(
            "{text}[camera]\nkind = \"pinhole\"\nposition = [3, 0, 0]\nlook_at = [0, 0, 0]\n"
        );
        let scene = lucent::scene::Scene::parse(&text, std::path::Path::new("s.toml")).unwrap();
        for entry in registry.entries() {
            let solver = registry.build(entry.name, &Params::default()).unwrap();
            if !solver.pages() {
                continue;
            }
            let at = |budget: u64| {
                let options = SolveOptions {
                    memory_budget: budget,
                    ..SolveOptions::default()
                };
                scene.build_paged_for(solver.as_ref(), &options)
            };
            let smallest = match at(64 << 10) {
                Err(lucent::Error::PagedBudget {
                    smallest: Some(s), ..
                }) => s,
                // The solver does not take this scene out of core (a light it cannot
                // march): it says so, whatever the budget.
                Err(lucent::Error::Solve(SolveError::Unsupported { .. })) => continue,
                other => panic!("{}: {:?}", entry.name, other.map(|_| "built")),
            };
            assert!(at(smallest).is_ok(), "{} at {smallest}", entry.name);
            assert!(
                matches!(
                    at(smallest * 95 / 100),
                    Err(lucent::Error::PagedBudget { .. })
                ),
                "{} 5 % below {smallest}",
                entry.name
            );
            checked += 1;
        }
    }
    assert!(checked >= 5, "{checked} solver and scene pairs");
}
