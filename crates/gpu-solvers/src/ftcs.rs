//! `gpu-ftcs-diffusion`: `ftcs-diffusion` on the device. Both march
//! V dφ/dτ = b − Aφ on exactly the discrete problem `diffusion-mg` solves
//! (lucent-diffusion's assembled system: reduced-intensity source, Robin boundaries,
//! embedded surfaces) with φ′ = φ + (cΔt/V)(b − Aφ), cΔt = `step_fraction` × the
//! Gershgorin bound 2V / max_i Σ_j |a_ij| (`lucent_explicit::steady::ftcs_limit`, checked
//! before running), to the caller's relative residual ‖b − Aφ‖/‖b‖.
//!
//! ## Correction form (defect correction)
//!
//! In f32 the residual b − Aφ cancels to rounding once φ has converged: measured on 32³
//! diffusion problems, plain f32 FTCS stalls at relative residuals of 3·10⁻⁷ (a point
//! source) to 1.4·10⁻⁵ (sources spread through the volume), above the default tolerance.
//! So the host keeps φ in f64 and the device iterates on the correction: with
//! r = b − Aφ computed on the host in f64, the device marches δ′ = δ + (cΔt/V)(r − Aδ)
//! from δ = 0, and when the device's residual ‖r − Aδ‖ has fallen by 10³ (or a stopping
//! rule fires) the host adds δ to φ and recomputes r in f64. FTCS is a stationary linear
//! iteration, so in exact arithmetic this is the same sequence of iterates as marching φ
//! itself; f32 now limits each correction to about 10⁻⁵ of itself, not the solution.
//! Every stopping decision that ends a solve is taken on the f64 residual.
//!
//! ## One submit per batch
//!
//! Steps are recorded `k` at a time into one command buffer (ping-pong fields, no host
//! round-trip per step). Each step's kernel also leaves the workgroup partial sums of r²
//! of the state it read, so the residual of every step reaches the host with the batch
//! (partials added in f64). `k` follows the observed convergence rate (the steps the rate
//! predicts to the tolerance, 1 to 64), so a solve runs at most a few steps past the
//! step where it converged; the report counts every step run.

use std::time::Instant;

use lucent_core::{Problem, StopReason, Stopping};
use lucent_diffusion::{
    AssembledSystem, Convergence, DiffusionError, DiffusionProblem, DiffusionSolution, Sources,
};
use lucent_explicit::FtcsDiffusionParams;
use lucent_explicit::steady::ftcs_limit;
use lucent_gpu::{
    DeviceField, DeviceIndices, GpuContext, GpuError, UniformSlots, WORKGROUP, groups_2d, shaders,
};

/// Most steps recorded into one submit.
const MAX_BATCH: usize = 64;
/// A correction is folded into the f64 solution once its residual has fallen this much.
const CORRECTION_GAIN: f64 = 1e-3;

/// The uniform block of `ftcs.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct StepParams {
    rows: u32,
    groups_x: u32,
    offset: u32,
    write: u32,
    scale: f32,
    pad: [f32; 3],
}

/// Bytes at peak: on the host the assembled system as `ftcs-diffusion` builds it (600
/// bytes per cell, see lucent-explicit) plus the f64 solution and residual and their f32
/// copies, per channel; on the device one channel's CSR system (7 × 8 + 4 bytes per row),
/// right-hand side, two corrections and 65 steps of partials (about 88 bytes per cell).
pub(crate) fn memory_bytes(problem: &Problem) -> u64 {
    let n = problem.geometry().voxel_count() as u64;
    n * (600 + 24) * problem.channels() as u64 + n * 88
}

fn gpu(e: GpuError) -> DiffusionError {
    DiffusionError::Invalid(format!("GPU: {e}"))
}

/// r = b − Aφ in f64 and its norm.
fn residual(system: &AssembledSystem, phi: &[f64]) -> (Vec<f64>, f64) {
    let r: Vec<f64> = system
        .rhs
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let ax: f64 = system
                .matrix
                .outer_view(i)
                .map_or(0.0, |row| row.iter().map(|(j, v)| v * phi[j]).sum());
            b - ax
        })
        .collect();
    let norm = r.iter().map(|v| v * v).sum::<f64>().sqrt();
    (r, norm)
}

/// FTCS to steady state on one channel's system, on `context`'s device.
pub(crate) fn steady(
    context: &GpuContext,
    d: &DiffusionProblem,
    s: &Sources,
    stop: &Stopping,
    params: &FtcsDiffusionParams,
    volume: f64,
    name: &str,
) -> Result<DiffusionSolution, DiffusionError> {
    let t0 = Instant::now();
    let system = d.assemble(s)?;
    let time_step = params.step_fraction * ftcs_limit(&system, volume);
    if !(time_step > 0.0 && time_step.is_finite()) {
        return Err(DiffusionError::Invalid(format!(
            "{name}: time step {time_step}"
        )));
    }
    let out = march(context, &system, time_step / volume, stop).map_err(gpu)?;
    let mut fluence = vec![0.0; d.cells().geometry().voxel_count()];
    for (&c, v) in system.cells.iter().zip(&out.phi) {
        fluence[c] = *v;
    }
    let balance = d.balance(s, &fluence);
    let bytes = (system.matrix.nnz() * 8 + system.rhs.len() * 4 * 4) as u64;
    Ok(DiffusionSolution {
        convergence: Convergence {
            residuals: out.residuals,
            stop_reason: out.stop_reason,
        },
        balance,
        // Assembly and the device's setup (uploads, kernels).
        setup_seconds: t0.elapsed().as_secs_f64() - out.solve_seconds,
        solve_seconds: out.solve_seconds,
        levels: 1,
        memory_bytes: bytes.max((system.matrix.nnz() * 16 + fluence.len() * 32) as u64),
        fluence,
    })
}

/// What [`march`] returns.
struct Marched {
    phi: Vec<f64>,
    residuals: Vec<f64>,
    stop_reason: StopReason,
    solve_seconds: f64,
}

/// φ′ = φ + scale (b − Aφ) from zero to `stop`, in correction form.
fn march(
    context: &GpuContext,
    system: &AssembledSystem,
    scale: f64,
    stop: &Stopping,
) -> Result<Marched, GpuError> {
    let a = &system.matrix;
    let n = system.rhs.len();
    let rows = u32::try_from(n).map_err(|_| GpuError::OverBudget {
        what: "FTCS rows".into(),
        limit: "u32 indices",
        needed: n as u64 * 4,
        available: u64::from(u32::MAX),
    })?;
    let to_u32 = |v: &[usize]| v.iter().map(|&i| i as u32).collect::<Vec<u32>>();
    let row_start =
        DeviceIndices::upload(context, "row starts", &to_u32(a.indptr().raw_storage()))?;
    let columns = DeviceIndices::upload(context, "columns", &to_u32(a.indices()))?;
    let entries: Vec<f32> = a.data().iter().map(|&v| v as f32).collect();
    let entries = DeviceField::upload(context, "matrix entries", &entries, false)?;
    let rhs = DeviceField::zeros(context, "residual of the f64 solution", n)?;
    let state = [
        DeviceField::zeros(context, "correction (even)", n)?,
        DeviceField::zeros(context, "correction (odd)", n)?,
    ];
    let groups = groups_2d(context, n as u64, WORKGROUP);
    let per_step = (groups[0] * groups[1]) as usize;
    let partials = DeviceField::zeros(context, "residual partials", (MAX_BATCH + 1) * per_step)?;
    let kernel = context.kernel("ftcs.wgsl", shaders::FTCS, "step")?;
    // Slot j: step j of a batch (write), slot MAX_BATCH + 1 + j: the residual of the
    // state after j steps (no write).
    let slots: Vec<StepParams> = (0..=MAX_BATCH)
        .map(|j| (j, 1))
        .chain((0..=MAX_BATCH).map(|j| (j, 0)))
        .map(|(j, write)| StepParams {
            rows,
            groups_x: groups[0],
            offset: (j * per_step) as u32,
            write,
            scale: scale as f32,
            pad: [0.0; 3],
        })
        .collect();
    let uniforms = UniformSlots::new(context, "ftcs steps", &slots)?;
    // bind[p][slot]: reads state[p], writes state[1 − p].
    let bind = [0usize, 1].map(|p| {
        (0..slots.len())
            .map(|slot| {
                kernel.bind(
                    context,
                    &[
                        row_start.binding(),
                        columns.binding(),
                        entries.binding(),
                        rhs.binding(),
                        state[p].binding(),
                        state[1 - p].binding(),
                        partials.binding(),
                        uniforms.slot(slot),
                    ],
                )
            })
            .collect::<Result<Vec<_>, _>>()
    });
    let [even, odd] = bind;
    let bind = [even?, odd?];
    let started = Instant::now();

    let b_norm = system
        .rhs
        .iter()
        .map(|v| v * v)
        .sum::<f64>()
        .sqrt()
        .max(f64::MIN_POSITIVE);
    let mut phi = vec![0.0f64; n];
    let (mut r, mut outer) = (system.rhs.clone(), b_norm);
    let upload = |r: &[f64]| -> Result<(), GpuError> {
        let r32: Vec<f32> = r.iter().map(|&v| v as f32).collect();
        rhs.write(context, &r32, false)
    };
    let mut residuals = vec![outer / b_norm];
    let verdict = |iteration: usize, relative: f64, residuals: &[f64]| {
        stop.verdict(
            iteration,
            relative,
            relative * b_norm,
            residuals[0],
            started,
        )
    };
    let finish = |phi: Vec<f64>, residuals, stop_reason| Marched {
        phi,
        residuals,
        stop_reason,
        solve_seconds: started.elapsed().as_secs_f64(),
    };
    if let Some(reason) = verdict(0, residuals[0], &residuals) {
        return Ok(finish(phi, residuals, reason));
    }
    upload(&r)?;
    let mut parity = 0usize;
    let mut iteration = 0usize;
    let mut batch = 4usize;
    loop {
        let k = crate::solver::bounded_batch(
            batch,
            n,
            crate::solver::cell_steps_per_submit(context, 1),
        )
        .min(MAX_BATCH)
        .min(stop.max_iterations.saturating_sub(iteration))
        .max(1);
        context.submit_pass("gpu-ftcs-diffusion", |pass| {
            for j in 0..k {
                kernel.dispatch(pass, &bind[(parity + j) % 2][j], groups);
            }
            // The residual of the state after the last step.
            kernel.dispatch(pass, &bind[(parity + k) % 2][MAX_BATCH + 1 + k], groups);
        })?;
        let sums = partials.download_prefix(context, (k + 1) * per_step)?;
        parity = (parity + k) % 2;
        // Residual norms of the states after steps 1..=k (partials of step j are of
        // the state before it; the state after the batch has its own slot, k).
        let norms: Vec<f64> = (1..=k)
            .map(|j| {
                sums[j * per_step..(j + 1) * per_step]
                    .iter()
                    .map(|&p| f64::from(p))
                    .sum::<f64>()
                    .sqrt()
            })
            .collect();
        let mut stopped = None;
        for norm in &norms {
            iteration += 1;
            let relative = norm / b_norm;
            residuals.push(relative);
            if let Some(reason) = verdict(iteration, relative, &residuals) {
                stopped = Some(reason);
            }
        }
        let last = *norms.last().unwrap_or(&outer);
        let diverged = matches!(
            stopped,
            Some(StopReason::DivergedGrowth { .. } | StopReason::DivergedNonFinite { .. })
        );
        if diverged {
            let delta = state[parity].download(context)?;
            for (p, d) in phi.iter_mut().zip(&delta) {
                *p += f64::from(*d);
                if !p.is_finite() {
                    *p = 0.0;
                }
            }
            return Ok(finish(phi, residuals, stopped.unwrap_or(StopReason::Exact)));
        }
        if stopped.is_some() || last <= CORRECTION_GAIN * outer {
            // Fold the correction into the f64 solution and take its f64 residual.
            let delta = state[parity].download(context)?;
            for (p, d) in phi.iter_mut().zip(&delta) {
                *p += f64::from(*d);
            }
            (r, outer) = residual(system, &phi);
            let relative = outer / b_norm;
            if let Some(entry) = residuals.last_mut() {
                *entry = relative;
            }
            if let Some(reason) = verdict(iteration, relative, &residuals) {
                return Ok(finish(phi, residuals, reason));
            }
            upload(&r)?;
            state[parity].clear(context)?;
        }
        // The next batch: the steps the observed rate predicts to the tolerance.
        let first = norms.first().copied().unwrap_or(last);
        let rate = if norms.len() > 1 && first > 0.0 && last > 0.0 {
            (last / first).powf(1.0 / (norms.len() - 1) as f64)
        } else {
            0.0
        };
        let target = stop.relative_tolerance * b_norm;
        let current = last.min(outer);
        batch = if rate > 0.0 && rate < 1.0 && current > target {
            ((target / current).ln() / rate.ln()).ceil().max(1.0) as usize
        } else {
            2 * k
        }
        .clamp(1, MAX_BATCH);
    }
}
