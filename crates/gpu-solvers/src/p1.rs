//! `gpu-ftcs-p1`: `ftcs-p1` on the device. Murray's P1 system (thesis §3.4.2,
//! Eqs. 3.23–3.26) marched by FTCS on a homogeneous medium, zero beyond the grid:
//!
//! φ′ = (1 − K_φ) φ − r ∇·E + cΔt q,    E′ = (1 − K_E) E − (r/3) ∇φ,
//!
//! K_φ = cΔt σ_a, K_E = cΔt σ_t′, r = cΔt/h, collocated or staggered (MAC) layout, at
//! `step_fraction` of the largest step the correct von Neumann bounds allow
//! (`lucent_explicit::stability::p1`: collocated (1 − K_φ)(1 − K_E) + r² ≤ 1, staggered
//! with 4r²), refused beyond them (`SolveError::Unstable`) unless `allow_unstable`.
//!
//! Each step is two kernels that read the old state and write the new one (`p1.wgsl`,
//! `p1_flux.wgsl`; ping-pong φ, E_x, E_y, E_z), recorded up to 64 steps per submit. The
//! kernels leave per workgroup Σ(φ′ − φ)², Σφ′², max|φ′| and max|E′|, so the host applies
//! `ftcs-p1`'s stopping rule ‖φ′ − φ‖/‖φ′‖ and its growth monitor (10⁶ × the initial
//! field plus the sources over the run) to every step. A run the monitor stops is
//! replayed from zero to the last step it passed, so the fluence returned is that step's,
//! as on the CPU.
//!
//! Precision: f32 fields; the per-step change is measured to about 10⁻⁷ of ‖φ‖, so
//! tolerances below that end at the iteration limit (reported as such).

use lucent_core::driver::{Channel, Record};
use lucent_core::{History, Problem, SolveError};
use lucent_explicit::p1::Layout;
use lucent_explicit::{GrowthMonitor, Lattice, P1Params};
use lucent_gpu::{DeviceField, GpuContext, UniformSlots, WORKGROUP, groups_2d, shaders};
use lucent_optics::PhaseFunction;

use crate::solver::device_error;

const MAX_BATCH: usize = 64;

/// The uniform block of `p1.wgsl` and `p1_flux.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct P1Params32 {
    dims: [u32; 4],
    scheme: [u32; 4],
    rates: [f32; 4],
}

/// Bytes: on the host as `ftcs-p1` (its f64 fields), which bounds the f32 download too;
/// on the device φ and E twice, the source and 64 steps of partials (about 40 bytes per
/// cell).
pub(crate) fn memory_bytes(problem: &Problem) -> u64 {
    let n = problem.geometry().voxel_count() as u64;
    n * 8 * 2 * 4 * 2 * problem.channels() as u64 + n * 40
}

/// The device's fields: φ, E_x, E_y, E_z twice (ping-pong).
struct State {
    fields: [[DeviceField; 4]; 2],
}

/// Marches one channel to steady state; returns the fluence and the record.
pub(crate) fn march(
    gpu: &GpuContext,
    l: &Lattice,
    channel: &Channel<'_>,
    q: &[f64],
    params: &P1Params,
    name: &str,
) -> Result<(Vec<f32>, Record), SolveError> {
    let err = |e| device_error(name, e);
    let g = channel.problem.medium().phase.mean_cosine();
    // Homogeneous (the capabilities ask for it): any cell's coefficients.
    let sigma_t = f64::from(channel.coefficients.sigma_t[0]);
    let sigma_s = f64::from(channel.coefficients.sigma_s[0]);
    let (sigma_a, reduced) = (sigma_t - sigma_s, sigma_t - g * sigma_s);
    let staggered = params.layout == Layout::Staggered;
    let largest_step =
        lucent_explicit::stability::p1::largest_step(staggered, sigma_a, reduced, l.spacing);
    if largest_step <= 0.0 {
        return Err(SolveError::InvalidParameter {
            name: "medium".into(),
            reason: "P1 FTCS has no stable step without absorption".into(),
        });
    }
    let dt = params.step_fraction * largest_step;
    let (k_phi, k_flux) = (dt * sigma_a, dt * reduced);
    let r = dt / l.spacing;
    let limit = if staggered {
        lucent_explicit::stability::p1::staggered_limit(k_phi, k_flux)
    } else {
        lucent_explicit::stability::p1::collocated_limit(k_phi, k_flux)
    };
    let unstable = r > limit * (1.0 + 1e-12) || k_phi > 2.0 || k_flux > 2.0;
    if unstable && !params.allow_unstable {
        return Err(SolveError::Unstable {
            solver: name.into(),
            parameter: "r = cΔt/h".into(),
            limit: limit * l.spacing,
            requested: dt,
        });
    }
    let stopping = &channel.stopping;
    let n = l.len();
    let source: Vec<f32> = q.iter().map(|&v| v as f32).collect();
    let source = DeviceField::upload(gpu, "P1 source", &source, false).map_err(err)?;
    let field = |what: &str| DeviceField::zeros(gpu, what, n).map_err(err);
    let state = State {
        fields: [
            [field("φ")?, field("E_x")?, field("E_y")?, field("E_z")?],
            [field("φ′")?, field("E_x′")?, field("E_y′")?, field("E_z′")?],
        ],
    };
    let groups = groups_2d(gpu, n as u64, WORKGROUP);
    let per_step = (groups[0] * groups[1]) as usize;
    let partials = DeviceField::zeros(gpu, "P1 partials", 4 * MAX_BATCH * per_step).map_err(err)?;
    let fluence_kernel = gpu
        .kernel("p1.wgsl", shaders::P1, "fluence_step")
        .map_err(err)?;
    let flux_kernel = gpu
        .kernel("p1_flux.wgsl", shaders::P1_FLUX, "flux_step")
        .map_err(err)?;
    let slots: Vec<P1Params32> = (0..MAX_BATCH)
        .map(|j| P1Params32 {
            dims: [
                l.dims[0] as u32,
                l.dims[1] as u32,
                l.dims[2] as u32,
                groups[0],
            ],
            scheme: [u32::from(staggered), (j * per_step) as u32, 0, 0],
            rates: [k_phi as f32, k_flux as f32, r as f32, dt as f32],
        })
        .collect();
    let uniforms = UniformSlots::new(gpu, "P1 steps", &slots).map_err(err)?;
    let mut binds = Vec::with_capacity(2);
    for p in 0..2 {
        let (from, to) = (&state.fields[p], &state.fields[1 - p]);
        let mut per_slot = Vec::with_capacity(MAX_BATCH);
        for j in 0..MAX_BATCH {
            let fluence = fluence_kernel
                .bind(
                    gpu,
                    &[
                        from[0].binding(),
                        from[1].binding(),
                        from[2].binding(),
                        from[3].binding(),
                        source.binding(),
                        to[0].binding(),
                        partials.binding(),
                        uniforms.slot(j),
                    ],
                )
                .map_err(err)?;
            let flux = flux_kernel
                .bind(
                    gpu,
                    &[
                        from[0].binding(),
                        from[1].binding(),
                        from[2].binding(),
                        from[3].binding(),
                        to[1].binding(),
                        to[2].binding(),
                        to[3].binding(),
                        partials.binding(),
                        uniforms.slot(j),
                    ],
                )
                .map_err(err)?;
            per_slot.push((fluence, flux));
        }
        binds.push(per_slot);
    }
    // Records `k` steps from the state in fields[parity].
    let run = |parity: usize, k: usize| {
        gpu.submit_pass("gpu-ftcs-p1", |pass| {
            for j in 0..k {
                let (fluence, flux) = &binds[(parity + j) % 2][j];
                fluence_kernel.dispatch(pass, fluence, groups);
                flux_kernel.dispatch(pass, flux, groups);
            }
        })
        .map_err(err)
    };
    let largest_source = q.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    let monitor = GrowthMonitor {
        reference: largest_source * dt * stopping.max_iterations.min(1 << 40) as f64
            + f64::MIN_POSITIVE,
        factor: 1e6,
    };
    let mut history = History::start();
    let mut step = 0usize;
    let mut parity = 0usize;
    let mut batch = 8usize;
    let stop_reason = loop {
        let k =
            crate::solver::bounded_batch(batch, n, crate::solver::cell_steps_per_submit(gpu, 2))
                .min(MAX_BATCH)
                .min(stopping.max_iterations.saturating_sub(step))
                .max(1);
        run(parity, k)?;
        let sums = partials
            .download_prefix(gpu, 4 * k * per_step)
            .map_err(err)?;
        let mut stopped = None;
        let mut changes = Vec::with_capacity(k);
        for j in 0..k {
            let block = &sums[4 * j * per_step..4 * (j + 1) * per_step];
            let (mut change, mut size, mut largest) = (0.0f64, 0.0f64, 0.0f64);
            for w in block.chunks_exact(4) {
                change += f64::from(w[0]);
                size += f64::from(w[1]);
                let most = f64::from(w[2].max(w[3]));
                largest = largest.max(if most >= 3.0e38 { f64::INFINITY } else { most });
            }
            let at = step + j + 1;
            if let Some(reason) = monitor.check_largest(largest, at) {
                // Replay from zero to the last step the monitor passed.
                for f in state.fields.iter().flatten() {
                    f.clear(gpu).map_err(err)?;
                }
                let mut done = 0;
                parity = 0;
                while done < at - 1 {
                    let m = (at - 1 - done).min(MAX_BATCH);
                    run(parity, m)?;
                    parity = (parity + m) % 2;
                    done += m;
                }
                let fluence = state.fields[parity][0].download(gpu).map_err(err)?;
                let mut record = Record::from_residuals(history.into_residuals(), reason, 0);
                record.iterations = at;
                record.memory_bytes = (n * 8 * 4) as u64;
                return Ok((fluence, record));
            }
            let relative = if size > 0.0 {
                (change / size).sqrt()
            } else {
                change.sqrt()
            };
            changes.push(relative);
            if let Some(reason) = history.record_step(stopping, at, relative, change.sqrt()) {
                stopped = Some(reason);
            }
        }
        step += k;
        parity = (parity + k) % 2;
        if let Some(reason) = stopped {
            break reason;
        }
        batch = crate::solver::next_batch(&changes, stopping.relative_tolerance, MAX_BATCH);
    };
    let fluence = state.fields[parity][0].download(gpu).map_err(err)?;
    let mut record = Record::from_residuals(history.into_residuals(), stop_reason, 0);
    record.iterations = step;
    record.memory_bytes = (n * 8 * 4) as u64;
    Ok((fluence, record))
}
