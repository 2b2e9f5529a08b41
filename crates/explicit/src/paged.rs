//! `convection-diffusion` on a paged medium (`lucent_core::PagedProblem`): Zhang & Ma's
//! absorption march by short characteristics, one pass per distant light, plane by plane
//! across the light's dominant axis ([`crate::convection::march_distant_planes`]), reading
//! σ_t one plane at a time from the paged field and writing each light's field one plane
//! at a time; then the lights composed brick layer by brick layer into the paged fluence.
//! The march is the in-memory one (the same plane march, the same per-cell code), and each
//! light's field is stored in f32 on both paths before composing, so the fluence has the
//! in-memory solve's bits. Memory: two planes of ρ and σ_a per march, one brick layer of
//! slabs per light while composing, besides the pool.

use lucent_core::{
    Boundary, Light, PagedProblem, PagedSolution, Progress, SolveError, SolveOptions, SolveReport,
    StopReason, paging_error,
};
use rayon::prelude::*;

use crate::lattice::Lattice;

/// What [`convection`] checks before any work: the problem's kind (a vacuum box, distant
/// lights, cubic cells) and the bytes it needs: the pool, the bookkeeping of every field
/// (the medium, each light's field, the fluence per channel), a march's four planes (f64 ρ
/// and σ_a, this one and upstream, and one in f32), and one brick layer per light and the
/// output while composing. Returns the lights' directions, the lattice and the bytes.
pub(crate) fn convection_needs(
    name: &str,
    problem: &PagedProblem,
    options: &SolveOptions,
) -> Result<(Vec<glam::DVec3>, Lattice, u64), SolveError> {
    let unsupported = |feature: String| SolveError::Unsupported {
        solver: name.into(),
        feature,
    };
    if !matches!(problem.boundary(), Boundary::Vacuum) {
        return Err(unsupported(format!("a {} boundary", problem.boundary())));
    }
    let mut directions = Vec::new();
    for light in problem.lights() {
        match light {
            Light::Directional { direction, .. } => directions.push(*direction),
            other => {
                return Err(unsupported(format!(
                    "{:?} lights on a paged medium (distant lights march plane by plane; a point light's shells do not)",
                    other.kind()
                )));
            }
        }
    }
    let geometry = *problem.geometry();
    let h = geometry.spacing();
    if h.x != h.y || h.y != h.z {
        return Err(unsupported("cells that are not cubes".into()));
    }
    let mut lattice =
        Lattice::new(geometry.dims(), h.x).map_err(|e| SolveError::InvalidParameter {
            name: "grid".into(),
            reason: e.to_string(),
        })?;
    lattice.origin = geometry.origin();
    let [nx, ny, nz] = geometry.dims();
    let layout = *problem.layout();
    let b = layout.brick();
    let channels = problem.channels();
    let lights = directions.len();
    let medium = problem.medium();
    let fields = medium.sigma_t.len() + medium.albedo.len() + lights + channels;
    let largest_plane = (nx * ny).max(ny * nz).max(nz * nx) as u64;
    let pool = problem.pager().capacity() as u64 * layout.stored_len() as u64 * 4;
    let needed = pool
        + problem.overhead_bytes(fields)
        + largest_plane * (4 * 8 + 4)
        + (nx * ny * b) as u64 * 4 * (lights as u64 + 1);
    if needed > options.memory_budget {
        return Err(SolveError::OverBudget {
            solver: name.into(),
            needed,
            budget: options.memory_budget,
        });
    }
    Ok((directions, lattice, needed))
}

/// The march of every channel's lights and their composition.
pub(crate) fn convection(
    name: &str,
    problem: &PagedProblem,
    options: &SolveOptions,
) -> Result<PagedSolution, SolveError> {
    let started = std::time::Instant::now();
    let meter = lucent_core::memory::PeakMeter::start();
    let before = problem.pager().stats();
    let err = |e| paging_error(name, e);
    let (directions, lattice, needed) = convection_needs(name, problem, options)?;
    let interrupt = lucent_core::Interrupt::of(options);
    let geometry = *problem.geometry();
    let [nx, ny, nz] = geometry.dims();
    let layout = *problem.layout();
    let b = layout.brick();
    let channels = problem.channels();
    let lights = directions.len();
    let medium = problem.medium();

    let work = (channels * (lights + 1)).max(1) as f64;
    let mut done = 0.0;
    let mut fluence = Vec::with_capacity(channels);
    for c in 0..channels {
        let sigma_t = &medium.sigma_t[c.min(medium.sigma_t.len() - 1)];
        let mut light_fields = Vec::with_capacity(lights);
        for direction in &directions {
            let field = problem.new_field().map_err(err)?;
            let mut plane32 = Vec::new();
            let marched = crate::convection::march_distant_planes(
                &lattice,
                *direction,
                |axis, p, out| {
                    // Asked every plane (a plane of 1024² cells through the pager takes
                    // tens of milliseconds; a march, minutes): the march ends there.
                    if interrupt.halted() {
                        return Err(lucent_paging::PagingError::Shape("interrupted".into()));
                    }
                    plane32.resize(out.len(), 0.0);
                    sigma_t.read_plane(axis, p, &mut plane32)?;
                    for (o, v) in out.iter_mut().zip(&plane32) {
                        *o = f64::from(*v);
                    }
                    Ok(())
                },
                |axis, p, values| {
                    let stored: Vec<f32> = values.iter().map(|&v| v as f32).collect();
                    field.write_plane(axis, p, &stored)
                },
            );
            interrupt.check(name, "the paged absorption march")?;
            marched.map_err(err)?;
            light_fields.push(field);
            done += 1.0;
            options.report(Progress {
                stage: "light march",
                fraction: (done / work).min(0.999),
                iteration: 1,
                residual: None,
            });
        }
        // Compose: Σ_k colour_k(c) ρ_k in f64, in the lights' order, as in memory.
        let colours: Vec<f64> = problem
            .lights()
            .iter()
            .map(|l| l.spectrum().channel(c))
            .collect();
        let out = problem.new_field().map_err(err)?;
        let mut slabs: Vec<Vec<f32>> = vec![Vec::new(); lights];
        for layer in 0..layout.bricks()[2] {
            let (z0, z1) = (layer * b, (layer * b + b).min(nz));
            let n = nx * ny * (z1 - z0);
            for (field, buffer) in light_fields.iter().zip(&mut slabs) {
                buffer.resize(n, 0.0);
                field.read_slabs(z0, z1, buffer).map_err(err)?;
            }
            let mut total = vec![0f32; n];
            total.par_iter_mut().enumerate().for_each(|(i, t)| {
                let mut sum = 0.0f64;
                for (k, buffer) in colours.iter().zip(&slabs) {
                    sum += k * f64::from(buffer[i]);
                }
                *t = sum as f32;
            });
            if let Some(i) = total.iter().position(|v| !v.is_finite()) {
                return Err(SolveError::NonFiniteOutput {
                    solver: name.into(),
                    what: "fluence",
                    channel: c,
                    cell: [i % nx, (i / nx) % ny, z0 + i / (nx * ny)],
                    value: total[i],
                });
            }
            out.write_slabs(z0, &total).map_err(err)?;
        }
        fluence.push(out);
        done += 1.0;
    }
    let after = problem.pager().stats();
    options.report(Progress {
        stage: Progress::DONE,
        fraction: 1.0,
        iteration: 1,
        residual: None,
    });
    Ok(PagedSolution {
        fluence,
        standard_error: Vec::new(),
        transmittance: Vec::new(),
        isotropic_fluence: Vec::new(),
        report: SolveReport {
            solver: name.into(),
            iterations: usize::from(lights > 0),
            residual_history: Vec::new(),
            wall_time_s: started.elapsed().as_secs_f64(),
            peak_memory_bytes: needed,
            measured_peak_bytes: meter.and_then(|m| m.peak_bytes()),
            stop_reason: StopReason::Exact,
            paging: Some(after.since(&before)),
            choice: None,
            composition: None,
        },
        paging: after.since(&before),
    })
}
