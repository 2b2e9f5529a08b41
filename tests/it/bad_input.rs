//! Bad numbers everywhere a user can put one: NaN, ±∞, negative, zero and huge values for
//! every numeric field of `Problem`, `SolveOptions`, each solver's parameters and the
//! scene file. Each gives a typed error or a finite result — never a panic, never a
//! non-finite output, never a hang (every solve runs under a time budget and the test
//! checks the wall time).

use std::time::{Duration, Instant};

use glam::DVec3;
use lucent::core::{
    Boundary, Field, Light, Medium, ParamValue, Params, Problem, SolveOptions, Spectrum,
};
use lucent::grid::{Grid, GridGeometry};
use lucent::optics::Phase;
use proptest::prelude::*;

/// The values that break code: NaN, both infinities, negative, zero, tiny, huge, and one
/// ordinary value so that some cases get further.
fn nasty() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(-1.0),
        Just(0.0),
        Just(1e-300),
        Just(1e300),
        Just(3.5e38),
        Just(1e30),
        Just(0.5),
        Just(2.0),
    ]
}

/// Runs every registered solver that admits `problem` with `options` (and a 2 s budget),
/// and checks what comes back.
fn every_solver_survives(problem: &Problem, options: &SolveOptions) {
    let registry = lucent::registry();
    for entry in registry.entries() {
        let mut params = Params::default();
        if entry.name == "mc" {
            params.0.insert("particles".into(), ParamValue::Int(200));
            params.0.insert("batches".into(), ParamValue::Int(2));
        }
        let solver = registry.build(entry.name, &params).unwrap();
        if solver.admits(problem).is_err() {
            continue;
        }
        let options = SolveOptions {
            time_budget: Some(options.time_budget.unwrap_or(Duration::from_secs(2))),
            ..options.clone()
        };
        let started = Instant::now();
        if let Ok(solution) = solver.solve(problem, &options) {
            for phi in &solution.fluence {
                assert!(
                    phi.data().iter().all(|v| v.is_finite()),
                    "{}: non-finite fluence",
                    entry.name
                );
            }
        }
        // Generous: the budget is checked between iterations, and set-up comes first.
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "{} took {:?}",
            entry.name,
            started.elapsed()
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// The problem's numbers: extinction, albedo, phase, light power, direction and
    /// position, the boundary's index. `Problem::new` refuses or the solvers cope.
    #[test]
    fn problems_built_from_bad_numbers(
        sigma in nasty(),
        albedo in nasty(),
        g in nasty(),
        power in nasty(),
        direction in (nasty(), nasty(), nasty()),
        position in (nasty(), nasty(), nasty()),
        eta in nasty(),
        which in 0usize..3,
    ) {
        let geometry = GridGeometry::new([5, 4, 3], DVec3::splat(0.25), DVec3::ZERO).unwrap();
        let phase = match Phase::henyey_greenstein(g) {
            Ok(p) => p,
            Err(_) => Phase::Isotropic,
        };
        let medium = Medium {
            sigma_t: vec![Grid::filled(geometry, sigma as f32)],
            albedo: vec![Field::Constant(albedo as f32)],
            phase,
        };
        let light = match which {
            0 => Light::Directional {
                direction: DVec3::new(direction.0, direction.1, direction.2),
                irradiance: Spectrum::Grey(power),
            },
            1 => Light::Point {
                position: DVec3::new(position.0, position.1, position.2),
                intensity: Spectrum::Grey(power),
            },
            _ => Light::Sky { radiance: Spectrum::Rgb([power, 1.0, 0.5]) },
        };
        let boundary = if eta > 0.0 { Boundary::Robin { eta } } else { Boundary::Vacuum };
        if let Ok(problem) = Problem::new(geometry, medium, vec![light], boundary, None) {
            every_solver_survives(&problem, &SolveOptions { max_iterations: 50, ..Default::default() });
        }
    }

    /// The options' numbers: tolerances, iteration limit, time budget, threads, memory.
    #[test]
    fn solves_asked_with_bad_options(
        relative in nasty(),
        absolute in nasty(),
        iterations in prop_oneof![Just(0usize), Just(1), Just(7), Just(usize::MAX)],
        budget in prop_oneof![Just(None), Just(Some(Duration::ZERO)), Just(Some(Duration::from_millis(50)))],
        threads in prop_oneof![Just(None), Just(Some(0usize)), Just(Some(1)), Just(Some(2)), Just(Some(1 << 40))],
        memory in prop_oneof![Just(0u64), Just(1), Just(1 << 20), Just(u64::MAX)],
    ) {
        let geometry = GridGeometry::new([5, 4, 3], DVec3::splat(0.25), DVec3::ZERO).unwrap();
        let medium = Medium {
            sigma_t: vec![Grid::filled(geometry, 3.0)],
            albedo: vec![Field::Constant(0.7)],
            phase: Phase::Isotropic,
        };
        let light = Light::Point { position: DVec3::new(0.6, 0.5, 0.4), intensity: Spectrum::Grey(1.0) };
        let problem = Problem::new(geometry, medium, vec![light], Boundary::Vacuum, None).unwrap();
        let options = SolveOptions {
            relative_tolerance: relative,
            absolute_tolerance: absolute,
            max_iterations: iterations.min(200),
            time_budget: budget,
            threads,
            memory_budget: memory,
            progress: None,
            cancel: None,
            ranks: None,
        };
        every_solver_survives(&problem, &options);
    }

    /// Every numeric solver parameter set to a bad number: the build refuses, or the solver
    /// copes on a small problem.
    #[test]
    fn solver_parameters_set_to_bad_numbers(value in nasty(), entry_index in 0usize..64, param_index in 0usize..16) {
        let registry = lucent::registry();
        let entry = registry.entries()[entry_index % registry.entries().len()];
        let docs = (entry.params)();
        if docs.is_empty() {
            return Ok(());
        }
        let doc = &docs[param_index % docs.len()];
        let mut params = Params::default();
        if entry.name == "mc" {
            params.0.insert("particles".into(), ParamValue::Int(200));
            params.0.insert("batches".into(), ParamValue::Int(2));
        }
        let integer = !doc.default.contains('.') && doc.default.parse::<i64>().is_ok();
        let v = if integer && value.is_finite() && value.abs() < 9e18 {
            ParamValue::Int(value as i64)
        } else {
            ParamValue::Float(value)
        };
        params.0.insert(doc.name.clone(), v);
        // A number that is not finite means nothing: refused, never read as "unset" (JSON,
        // which the parameters pass through, turns NaN and infinity into null).
        if !value.is_finite() {
            let refused = registry.build(entry.name, &params).err().map(|e| e.to_string());
            prop_assert!(
                refused.as_deref().is_some_and(|m| m.contains("is not a finite number")),
                "{} {} = {value}: {refused:?}", entry.name, doc.name
            );
            return Ok(());
        }
        if let Ok(solver) = registry.build(entry.name, &params) {
            let geometry = GridGeometry::new([6, 6, 6], DVec3::splat(0.2), DVec3::ZERO).unwrap();
            let medium = Medium {
                sigma_t: vec![Grid::filled(geometry, 3.0)],
                albedo: vec![Field::Constant(0.7)],
                phase: Phase::Isotropic,
            };
            let light = Light::Point { position: DVec3::new(0.61, 0.59, 0.6), intensity: Spectrum::Grey(1.0) };
            let problem = Problem::new(geometry, medium, vec![light], Boundary::Vacuum, None).unwrap();
            if solver.admits(&problem).is_ok() {
                let options = SolveOptions {
                    max_iterations: 100,
                    time_budget: Some(Duration::from_secs(2)),
                    ..Default::default()
                };
                let started = Instant::now();
                if let Ok(solution) = solver.solve(&problem, &options) {
                    prop_assert!(solution.fluence.iter().all(|g| g.data().iter().all(|v| v.is_finite())));
                }
                prop_assert!(started.elapsed() < Duration::from_secs(30), "{} {}", entry.name, doc.name);
            }
        }
    }
}

/// Point lights at every distance a finite `f64` allows, on each side of the box and at
/// every power: the light is valid (finite position), so each solver answers with a finite
/// fluence or a typed refusal. Far lights once overflowed the device march's integer shell
/// index; the proptest above draws them only by chance, this walks them all.
#[test]
fn point_lights_far_from_the_box() {
    let geometry = GridGeometry::new([5, 4, 3], DVec3::splat(0.25), DVec3::ZERO).unwrap();
    let medium = Medium {
        sigma_t: vec![Grid::filled(geometry, 2.0)],
        albedo: vec![Field::Constant(0.5)],
        phase: Phase::Isotropic,
    };
    for far in [1e6, 1e12, 1e30, 3.5e38, 1e300, f64::MAX] {
        for position in [
            DVec3::new(-1.0, far, -1.0),
            DVec3::new(far, 0.5, 0.4),
            DVec3::new(0.6, 0.5, -far),
            DVec3::splat(-far),
        ] {
            for power in [1.0, 1e30, 1e300] {
                let light = Light::Point {
                    position,
                    intensity: Spectrum::Grey(power),
                };
                if let Ok(problem) = Problem::new(
                    geometry,
                    medium.clone(),
                    vec![light],
                    Boundary::Vacuum,
                    None,
                ) {
                    every_solver_survives(
                        &problem,
                        &SolveOptions {
                            max_iterations: 50,
                            ..Default::default()
                        },
                    );
                }
            }
        }
    }
}

/// Every bad number in every numeric field of a scene file, written as TOML (where `nan`
/// and `inf` are valid floats): refused when read or built, or solved by every solver to a
/// finite fluence. The 63 pairs are three tests of three fields each, run side by side.
fn scenes_with_bad_numbers(fields: std::ops::Range<usize>) {
    for field in fields {
        for value in [
            "nan",
            "inf",
            "-inf",
            "-1",
            "0",
            "1e300",
            "9223372036854775807",
        ] {
            let mut lines = [
                "density = 3.0",
                "albedo = 0.7",
                "irradiance = 1.0",
                "sigma = 0.2",
                "exposure = 0.0",
                "step = 0.5",
                "width = 64",
                "height = 48",
                "fov = 40",
            ];
            let key = lines[field].split(" = ").next().unwrap();
            let replaced = format!("{key} = {value}");
            lines[field] = &replaced;
            let text = format!(
                "[volume]\nkind = \"blob\"\nresolution = [8, 8, 8]\nbounds = [[0, 0, 0], [1, 1, 1]]\ncentre = [0.5, 0.5, 0.5]\n{}\n[medium]\n{}\n{}\n[[lights]]\nkind = \"directional\"\ndirection = [0.0, 0.0, -1.0]\n{}\n[camera]\nkind = \"pinhole\"\nposition = [3, 0, 0]\nlook_at = [0, 0, 0]\n{}\n[image]\n{}\n{}\n{}\n{}\n",
                lines[3],
                lines[0],
                lines[1],
                lines[2],
                lines[8],
                lines[4],
                lines[5],
                lines[6],
                lines[7]
            );
            let path = std::path::Path::new("bad.toml");
            if let Ok(scene) = lucent::scene::Scene::parse(&text, path)
                && let Ok(built) = scene.build_within(std::path::Path::new("."), 64 << 20)
            {
                let what = format!("{key} = {value}");
                assert!(
                    built.volume.data().iter().all(|v| v.is_finite()),
                    "{what}: non-finite volume"
                );
                assert!(built.exposure.is_finite(), "{what}: non-finite exposure");
                every_solver_survives(
                    &built.problem,
                    &SolveOptions {
                        max_iterations: 50,
                        ..Default::default()
                    },
                );
            }
        }
    }
}

#[test]
fn scenes_with_bad_numbers_in_the_medium_and_light() {
    scenes_with_bad_numbers(0..3);
}

#[test]
fn scenes_with_bad_numbers_in_the_volume_exposure_and_step() {
    scenes_with_bad_numbers(3..6);
}

#[test]
fn scenes_with_bad_numbers_in_the_image_and_camera() {
    scenes_with_bad_numbers(6..9);
}

/// A missing key is reported at the table that lacks it, with the table named in the
/// scene's words; a scene without `[volume]` is told it needs one.
#[test]
fn a_missing_key_names_its_table() {
    let error = |text: &str| {
        lucent::scene::Scene::parse(text, std::path::Path::new("s.toml"))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_else(|| panic!("accepted:\n{text}"))
    };
    let blob = "[volume]\nkind = \"blob\"\nresolution = [8, 8, 8]\nbounds = [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]\ncentre = [0.0, 0.0, 0.0]\nsigma = 0.3\n";
    let e = error(&format!(
        "{blob}\n[[lights]]\nkind = \"sky\"\nradiance = 1.0\n\n[[lights]]\nkind = \"point\"\nposition = [0.0, 0.0, 0.0]\n"
    ));
    assert!(e.contains("line 12"), "{e}");
    assert!(e.contains("`[[lights]]` needs `intensity`"), "{e}");
    let e = error("[volume]\nkind = \"cloud\"\nbounds = [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]\n");
    assert!(e.contains("`[volume]` needs `resolution`"), "{e}");
    let e = error("[medium]\ndensity = 3.0\n");
    assert!(e.contains("a scene needs a `[volume]` table"), "{e}");
    // A stray key beside a kind that has none is refused, not ignored.
    for stray in [
        "[boundary]\nkind = \"vacuum\"\neta = 1.3\n",
        "[medium.phase]\nkind = \"isotropic\"\ng = 0.8\n",
    ] {
        let e = error(&format!("{blob}{stray}"));
        assert!(e.contains("unknown field"), "{e}");
    }
}
