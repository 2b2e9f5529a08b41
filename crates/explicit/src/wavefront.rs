//! Zhang & Ma's absorption march of a distant light split over ranks by z-slabs or a
//! Cartesian grid of boxes: the twin of the one-pass marches of
//! [`crate::convection::propagate`] (ordered sweeps, inflow edges, the paper's Eq. 16 or
//! short characteristics), the same bits on any number of ranks and any decomposition
//! ([`propagate_on_ranks`] takes either).
//!
//! Over boxes ([`propagate_box`], [`read_box`]) the march is the KBA sweep of discrete
//! ordinates codes: tasks of a plane by a chunk of rows, one schedule of steps that every
//! rank derives alike, pipelined across every cut but those of one axis (the module
//! `boxes` has the construction). The rest of this page is the z-slab march.
//!
//! Rank r owns the z-layers [k0, k1) = [r n_z / P, (r + 1) n_z / P) ([`owned_layers`]) and
//! holds σ_a and ρ of those and of two more layers each side ([`read_layers`]), so
//! [`propagate_slab`] never needs the whole volume ([`propagate_on_ranks`] slices the
//! whole σ_a and gathers the whole ρ, for the registry). The march takes one of two
//! shapes, by how the light's dependencies cross the slabs:
//!
//! - **Across the slabs: a pipelined wavefront.** The paper's pass visits z outermost (its
//!   octant order), and the characteristic model marches planes across the light's
//!   dominant axis, z where |u_z| is the largest. Either way a rank's first layer reads
//!   only the last layer of its upstream neighbour (rank − 1 for u_z ≥ 0, else rank + 1),
//!   so whole slabs would run one after another. Instead every layer is cut into chunks of
//!   B rows along y (counted in the light's y order, q), and the rank at pipeline position
//!   π runs chunk c of all its layers at step π + c, then sends that chunk's rows of its
//!   last layer downstream: after P − 1 filling steps every rank works (the KBA sweep of
//!   discrete ordinates codes). The paper's cell reads the row upwind in y of its own layer
//!   and the same row of the layer upstream, so chunk c is rows [cB, (c + 1)B) of every
//!   layer. A short characteristic reads the upstream layer's rows q − 2 … q + 1 (its
//!   quadratic stencil reaches one row downwind too), so chunks are skewed: the cell of
//!   row q in the layer m-th in the march belongs to chunk ⌊(q + m)/B⌋, and every read
//!   lies in the same chunk or an earlier one.
//! - **Along the slabs: planes in lock step.** With x or y dominant the characteristic
//!   model's planes cut through every slab: all ranks march plane p together, each its
//!   own layers of it, reading plane p − 1 up to two layers into each neighbour (z in
//!   k − 2 … k + 2, so every slab needs two layers). Before each plane the ranks exchange
//!   their two edge rows of the previous one each way and compute meanwhile the rows that
//!   read no halo.
//!
//! Every cell is computed by the same function from the same values as in the serial
//! pass, so ρ is the serial ρ bit for bit.
//!
//! Cost, P ranks of H layers on an n_x × n_y × n_z grid: chunks are one row (B = 1) unless
//! a step would then hold fewer than 512 cells. The pipeline sends one message of at most
//! B n_x values per step. The paper's pass starts each rank one step after its upstream
//! neighbour, so against one rank's H layers it takes at most (P − 1 + n_y)/n_y times as
//! long; a short characteristic's first row depends on its upstream slab's rows 0 … H (the
//! downwind read, H layers deep), so each rank starts H + 1 steps after its neighbour:
//! ((P − 1)(H + 1) + n_y + H)/n_y (about 2 on a cube at large P: half the ranks' time is
//! filling). The lock step sends two messages of 2 n_l values (n_l the lateral extent) per
//! plane, hidden behind the plane's inner rows, and idles only in synchronisation.
//! BENCHMARKS.md ("Absorption march on ranks") has the measurements and the model at 64
//! and 1024 ranks.

use std::ops::Range;

use glam::DVec3;
use lucent_core::StopReason;
use lucent_core::ranks::{Communicator, exchange};
use rayon::prelude::*;

use crate::Lattice;
use crate::convection::{
    Edges, Light, Model, Propagation, Setup, Sweep, UpwindSettings, paper_row, propagate,
};
use crate::ranks::{Decomposition, DecompositionError};

mod boxes;
pub use boxes::{
    BoxSchedule, HALO, MAX_TASKS, STEP_CELLS, TASK_CELLS, box_schedule, march_boxes, propagate_box,
    rank_plan_tasks, read_box,
};

/// The z-layers rank `rank` of `size` owns: [rank·n_z/size, (rank + 1)·n_z/size).
pub fn owned_layers(nz: usize, size: usize, rank: usize) -> Range<usize> {
    rank * nz / size..(rank + 1) * nz / size
}

/// The z-layers of the absorption rank `rank` of `size` reads ([`propagate_slab`]): its
/// own and two more on each side within the grid (the lock step's halo; the pipeline
/// reads one upstream).
pub fn read_layers(nz: usize, size: usize, rank: usize) -> Range<usize> {
    let owned = owned_layers(nz, size, rank);
    owned.start.saturating_sub(2)..(owned.end + 2).min(nz)
}

/// Whether more than one rank can take this march: a distant light's one-pass march.
fn splits(light: &Light, settings: &UpwindSettings) -> bool {
    matches!(light, Light::Distant { .. })
        && settings.sweep == Sweep::Ordered
        && settings.edges == Edges::Inflow
        && settings.model != Model::Conservative
}

/// Why a march that [`splits`] refuses cannot run on more than one rank.
fn unsupported(light: &Light) -> DecompositionError {
    DecompositionError::Unsupported(
        if matches!(light, Light::Point { .. }) {
            "a point light's march over ranks (its cells go by distance from the light, \
             in passes until they settle): distant lights split over ranks"
        } else {
            "this march over ranks: only the one-pass marches split (ordered sweeps, \
             inflow edges, the paper's or the characteristic model)"
        }
        .into(),
    )
}

/// The checks every split march runs first: this rank's part of the absorption has the
/// length `wrong_length` accepts (it says why not) and passes the march's own checks.
/// Every rank's verdict is gathered, so a part refused on one rank stops every rank.
fn checked_part<'a>(
    lattice: &'a Lattice,
    absorption: &'a [f64],
    light: &Light,
    settings: &UpwindSettings,
    comm: &(impl Communicator + ?Sized),
    wrong_length: impl FnOnce(usize) -> Option<String>,
) -> Result<Setup<'a>, DecompositionError> {
    let (size, rank) = (comm.size(), comm.rank());
    // This rank's checks (its part's length and values, the light), then everyone's.
    let checked = match wrong_length(absorption.len()) {
        None => crate::convection::prepare_part(lattice, absorption, light, settings),
        Some(why) => Err(crate::ExplicitError::Invalid(format!("absorption: {why}"))),
    };
    let flags = comm.all_gather(&[if checked.is_ok() { 1.0 } else { 0.0 }]);
    let setup = checked?;
    if let Some(bad) = flags.iter().position(|&f| f != 1.0) {
        return Err(DecompositionError::Scheme(crate::ExplicitError::Invalid(
            format!("rank {bad} refused its part of the absorption (it says why)"),
        )));
    }
    if flags.len() != size {
        return Err(DecompositionError::Protocol { rank });
    }
    Ok(setup)
}

/// Marches one light on the ranks of `comm`, each computing its z-slab or box
/// (`decomposition`: [`Decomposition::Slabs`] are the layers [`owned_layers`] names,
/// [`Decomposition::Boxes`] one box per rank); the same result as [`propagate`] on every
/// rank. More than one rank takes the one-pass marches of a distant light only:
/// [`Sweep::Ordered`], [`Edges::Inflow`] and [`Model::Paper`] or
/// [`Model::Characteristic`]; the rest is [`DecompositionError::Unsupported`]. Every rank
/// holds the whole `absorption` and gets the whole ρ; [`propagate_slab`] and
/// [`propagate_box`] are the marches that hold only a rank's layers or box.
pub fn propagate_on_ranks(
    lattice: &Lattice,
    absorption: &[f64],
    light: &Light,
    settings: &UpwindSettings,
    decomposition: &Decomposition,
    comm: &(impl Communicator + ?Sized),
) -> Result<Propagation, DecompositionError> {
    let (size, rank) = (comm.size(), comm.rank());
    if size <= 1 && !splits(light, settings) {
        return Ok(propagate(lattice, absorption, light, settings)?);
    }
    // One rank that splits runs the split code too (so a weak-scaling measurement compares
    // the same kernel); it gives the same bits.
    lattice.check_field("absorption", absorption)?;
    if let Some(initial) = &settings.initial {
        lattice.check_field("initial", initial)?;
    }
    let [nx, ny, nz] = lattice.dims;
    let density = match decomposition {
        Decomposition::Slabs => {
            let reads = read_layers(nz, size, rank);
            let part = &absorption[reads.start * nx * ny..reads.end * nx * ny];
            let mine = propagate_slab(lattice, part, light, settings, comm)?;
            let density = comm.all_gather(&mine);
            if density.len() != lattice.len() {
                return Err(DecompositionError::Protocol { rank });
            }
            density
        }
        Decomposition::Boxes(boxes) => {
            let boxes = boxes.fitting(lattice.dims, size)?;
            let region = read_box(boxes, rank);
            let mut part = vec![0.0; region.iter().map(Range::len).product()];
            let grid = [0..nx, 0..ny, 0..nz];
            crate::ranks::copy_cells(absorption, &grid, &mut part, &region, &region);
            let mine = propagate_box(lattice, &part, light, settings, boxes, comm)?;
            boxes.gather(&mine, comm)?
        }
    };
    Ok(Propagation {
        density,
        iterations: 1,
        residuals: vec![0.0],
        stop_reason: StopReason::Exact,
    })
}

/// The march of [`propagate_on_ranks`] holding only this rank's layers: `absorption` is
/// σ_a of the layers [`read_layers`] names (as a rank reads them from a volume file with
/// `lucent_grid::io::layers`), and the result ρ of the layers [`owned_layers`] names, the
/// serial march's bits there. Memory per rank: two fields of (owned + 4) layers. The
/// march reads no starting field (`settings.initial` is ignored). Every rank checks its
/// absorption and all agree before marching, so a bad layer on one rank stops every rank
/// with an error, never a hang.
pub fn propagate_slab(
    lattice: &Lattice,
    absorption: &[f64],
    light: &Light,
    settings: &UpwindSettings,
    comm: &(impl Communicator + ?Sized),
) -> Result<Vec<f64>, DecompositionError> {
    let (size, rank) = (comm.size(), comm.rank());
    let [nx, ny, nz] = lattice.dims;
    if !splits(light, settings) {
        if size <= 1 {
            return Ok(propagate(lattice, absorption, light, settings)?.density);
        }
        return Err(unsupported(light));
    }
    if size > nz {
        return Err(DecompositionError::TooManyRanks {
            ranks: size,
            layers: nz,
        });
    }
    let layer_len = nx * ny;
    let reads = read_layers(nz, size, rank);
    let setup = checked_part(lattice, absorption, light, settings, comm, |len| {
        (len != reads.len() * layer_len)
            .then(|| format!("{len} values for layers {reads:?} of {nx} × {ny}"))
    })?;
    let Light::Distant { direction, density } = setup.light else {
        unreachable!("`splits` admits distant lights only");
    };
    let bounds: Vec<(usize, usize)> = (0..size)
        .map(|r| {
            let owned = owned_layers(nz, size, r);
            (owned.start, owned.end)
        })
        .collect();
    let mut rho = Local {
        values: vec![0.0; absorption.len()],
        first: reads.start * layer_len,
    };
    let axis = direction.abs().max_position();
    match setup.model {
        Model::Paper => pipeline(&setup, Some(density), &bounds, &mut rho, comm)?,
        _ if axis == 2 => pipeline(&setup, None, &bounds, &mut rho, comm)?,
        _ => lockstep(&setup, axis, &bounds, &mut rho, comm)?,
    }
    let (k0, k1) = bounds[rank];
    Ok(rho.values[k0 * layer_len - rho.first..k1 * layer_len - rho.first].to_vec())
}

/// A rank's ρ: the cells from `first` (a global index) on.
struct Local {
    values: Vec<f64>,
    first: usize,
}

/// [`propagate_on_ranks`] on `ranks` in-process ranks ([`lucent_core::ranks::Threads`]).
pub fn propagate_on_threads(
    lattice: &Lattice,
    absorption: &[f64],
    light: &Light,
    settings: &UpwindSettings,
    decomposition: &Decomposition,
    ranks: usize,
) -> Result<Propagation, DecompositionError> {
    crate::ranks::on_threads(ranks, |comm| {
        propagate_on_ranks(lattice, absorption, light, settings, decomposition, comm)
    })
}

/// The light of `setup` (distant: [`propagate_on_ranks`] checked it).
fn direction(setup: &Setup<'_>) -> DVec3 {
    match setup.light {
        Light::Distant { direction, .. } => direction,
        Light::Point { .. } => DVec3::Z,
    }
}

/// The pipelined wavefront (light across the slabs): the paper's pass when `paper` holds
/// the light's density, else the characteristic model's (z dominant).
fn pipeline(
    setup: &Setup<'_>,
    paper: Option<f64>,
    bounds: &[(usize, usize)],
    local: &mut Local,
    comm: &(impl Communicator + ?Sized),
) -> Result<(), DecompositionError> {
    let (size, rank) = (comm.size(), comm.rank());
    let [nx, ny, nz] = setup.lattice.dims;
    let layer_len = nx * ny;
    let u = direction(setup);
    // The light crosses the slabs upward (rank − 1 upstream) or downward; both as the
    // serial pass orders z (`paper_row`, `PlaneMarch`).
    let up = u.z >= 0.0;
    let forward_y = u.y >= 0.0;
    let (k0, k1) = bounds[rank];
    let position = if up { rank } else { size - 1 - rank };
    // Layers by their place m in the march, and rows by their place q in the light's y order.
    let layer = |m: usize| if up { m } else { nz - 1 - m };
    let row = |q: usize| if forward_y { q } else { ny - 1 - q };
    let mine = if up { k0..k1 } else { nz - k1..nz - k0 };
    // Rows per chunk: one, unless a step would then hold fewer than 512 cells (about
    // 130 µs on a core at 0.25 µs per cell), where a message's latency would start to count.
    let thickest = nz.div_ceil(size);
    let rows_per_chunk = 512usize.div_ceil(thickest * nx).clamp(1, ny);
    let chunks = match paper {
        Some(_) => ny.div_ceil(rows_per_chunk),
        None => (ny + nz - 1).div_ceil(rows_per_chunk),
    };
    // The rows (by q) of chunk c in the layer m-th in the march; skewed for characteristics.
    let rows = |c: usize, m: usize| -> Range<usize> {
        let shift = if paper.is_some() { 0 } else { m };
        let lo = (c * rows_per_chunk).saturating_sub(shift).min(ny);
        let hi = ((c + 1) * rows_per_chunk).saturating_sub(shift).min(ny);
        lo..hi
    };
    // Where row q of the layer m-th in the march starts in this rank's ρ.
    let first = local.first;
    let start = |q: usize, m: usize| row(q) * nx + layer(m) * layer_len - first;
    let rho = &mut local.values;
    let pack = |rho: &[f64], c: usize, m: usize| -> Vec<f64> {
        rows(c, m)
            .flat_map(|q| rho[start(q, m)..start(q, m) + nx].iter().copied())
            .collect()
    };
    for step in 0..chunks + size - 1 {
        let chunk = step.checked_sub(position).filter(|&c| c < chunks);
        if let Some(c) = chunk {
            for m in mine.clone() {
                match paper {
                    Some(density) => {
                        for q in rows(c, m) {
                            paper_row(setup, u, density, (rho, first), [q, m]);
                        }
                    }
                    None => {
                        // Into a buffer, then stored: a layer's cells read only the layer
                        // upstream. (`Setup::characteristic` on the whole ρ, as the serial
                        // march inlines it: in place through split slices ran 1.5 times
                        // slower.)
                        let values: Vec<f64> = {
                            let rho = &*rho;
                            rows(c, m)
                                .into_par_iter()
                                .flat_map_iter(|q| {
                                    let cell = start(q, m) + first;
                                    (cell..cell + nx)
                                        .map(|i| setup.characteristic_from(i, rho, first))
                                })
                                .collect()
                        };
                        for (q, values) in rows(c, m).zip(values.chunks(nx)) {
                            rho[start(q, m)..start(q, m) + nx].copy_from_slice(values);
                        }
                    }
                }
            }
        }
        // Downstream: this chunk's rows of the last layer; from upstream, its chunk of
        // this step (c + 1), which this rank runs next.
        let out = chunk.map_or_else(Vec::new, |c| pack(rho, c, mine.end - 1));
        let (to_below, to_above) = if up {
            (Vec::new(), out)
        } else {
            (out, Vec::new())
        };
        let (from_below, from_above) = comm.exchange_around(&to_below, &to_above, &mut || {});
        let incoming = if up { from_below } else { from_above };
        let upstream = (position > 0)
            .then(|| (step + 1).checked_sub(position))
            .flatten()
            .filter(|&c| c < chunks);
        let m = mine.start.wrapping_sub(1);
        let expected = upstream.map_or(0, |c| rows(c, m).len() * nx);
        if incoming.len() != expected {
            return Err(DecompositionError::Protocol { rank });
        }
        if let Some(c) = upstream {
            for (q, values) in rows(c, m).zip(incoming.chunks(nx)) {
                rho[start(q, m)..start(q, m) + nx].copy_from_slice(values);
            }
        }
    }
    Ok(())
}

/// Planes across x or y (`axis`, the light's dominant one) in lock step, each rank its
/// layers of each plane, two halo rows each way per plane.
fn lockstep(
    setup: &Setup<'_>,
    axis: usize,
    bounds: &[(usize, usize)],
    local: &mut Local,
    comm: &(impl Communicator + ?Sized),
) -> Result<(), DecompositionError> {
    let (size, rank) = (comm.size(), comm.rank());
    if let Some(thin) = bounds
        .iter()
        .position(|&(a, b)| b - a < 2)
        .filter(|_| size > 1)
    {
        return Err(DecompositionError::StencilTooWide { rank: thin });
    }
    let l = setup.lattice;
    let s = l.strides();
    let lateral = 1 - axis;
    let n_lateral = l.dims[lateral];
    let (k0, k1) = bounds[rank];
    let planes: Vec<usize> = if direction(setup)[axis] < 0.0 {
        (0..l.dims[axis]).rev().collect()
    } else {
        (0..l.dims[axis]).collect()
    };
    // Cells by their global index, and where they are in this rank's ρ.
    let first = local.first;
    let cell = |p: usize, t: usize, k: usize| p * s[axis] + t * s[lateral] + k * s[2];
    let here = |p: usize, t: usize, k: usize| cell(p, t, k) - first;
    let rho = &mut local.values;
    let compute = |rho: &[f64], p: usize, layers: Range<usize>| -> Vec<f64> {
        layers
            .into_par_iter()
            .flat_map_iter(|k| {
                (0..n_lateral).map(move |t| setup.characteristic_from(cell(p, t, k), rho, first))
            })
            .collect()
    };
    let store = |rho: &mut [f64], p: usize, layers: Range<usize>, values: &[f64]| -> bool {
        if values.len() != layers.len() * n_lateral {
            return false;
        }
        for (k, row) in layers.zip(values.chunks(n_lateral)) {
            for (t, v) in row.iter().enumerate() {
                rho[here(p, t, k)] = *v;
            }
        }
        true
    };
    let pack = |rho: &[f64], p: usize, layers: Range<usize>| -> Vec<f64> {
        layers
            .flat_map(|k| (0..n_lateral).map(move |t| here(p, t, k)))
            .map(|c| rho[c])
            .collect()
    };
    // Rows that read no halo (two from each slab edge), and the others.
    let low = k0..(k0 + 2).min(k1);
    let high = k1.saturating_sub(2).max(low.end)..k1;
    let inner = low.end..high.start;
    let protocol = DecompositionError::Protocol { rank };
    for (index, &p) in planes.iter().enumerate() {
        let Some(&before) = index.checked_sub(1).map(|i| &planes[i]) else {
            let values = compute(rho, p, k0..k1);
            store(rho, p, k0..k1, &values);
            continue;
        };
        let to_below = if rank > 0 {
            pack(rho, before, low.clone())
        } else {
            Vec::new()
        };
        let to_above = if rank + 1 < size {
            pack(rho, before, k1 - 2..k1)
        } else {
            Vec::new()
        };
        let (from_below, from_above, interior) = {
            let rho = &*rho;
            exchange(comm, &to_below, &to_above, || {
                compute(rho, p, inner.clone())
            })
        };
        if rank > 0 && !store(rho, before, k0 - 2..k0, &from_below)
            || rank + 1 < size && !store(rho, before, k1..k1 + 2, &from_above)
        {
            return Err(protocol);
        }
        store(rho, p, inner.clone(), &interior);
        for edge in [low.clone(), high.clone()] {
            let values = compute(rho, p, edge.clone());
            store(rho, p, edge, &values);
        }
    }
    Ok(())
}
