//! Streaming a paged field through a stencil, brick layer by brick layer, with the next
//! layer prefetched while the current one is worked on (Bernabei's precomputed streaming
//! order, for stencils the z-slab order).

use std::sync::mpsc;

use crate::error::PagingError;
use crate::field::PagedGrid;

/// Calls `body(layer, z_lo, window)` for every brick layer of `input` in z order, where
/// `window` holds slabs `z_lo ..` of the field around the layer (its cells and one slab
/// above and below, from the layer's stored bricks: [`PagedGrid::read_layer_window`]).
/// With `prefetch`, a helper thread loads the next layer's bricks (of `input` and of
/// every field in `also`, e.g. the output) while `body` runs.
pub fn for_each_layer(
    input: &PagedGrid,
    also: &[&PagedGrid],
    prefetch: bool,
    mut body: impl FnMut(usize, usize, &[f32]) -> Result<(), PagingError>,
) -> Result<(), PagingError> {
    let layers = input.layout().bricks()[2];
    let layer_bricks = |field: &PagedGrid, layer: usize| -> Vec<usize> {
        let layout = field.layout();
        let b = layout.brick();
        layout
            .bricks_of_slabs(layer * b, layer * b + 1)
            .map(|id| field.pager_brick(id))
            .collect()
    };
    std::thread::scope(|scope| {
        let (sender, receiver) = mpsc::channel::<usize>();
        let helper = prefetch.then(|| {
            scope.spawn(move || -> Result<(), PagingError> {
                for layer in receiver {
                    for field in std::iter::once(input).chain(also.iter().copied()) {
                        field.pager().prefetch(layer_bricks(field, layer))?;
                    }
                }
                Ok(())
            })
        });
        let mut result = Ok(());
        for layer in 0..layers {
            if prefetch && layer + 1 < layers {
                let _ = sender.send(layer + 1);
            }
            let (z_lo, window) = match input.read_layer_window(layer) {
                Ok(w) => w,
                Err(e) => {
                    result = Err(e);
                    break;
                }
            };
            if let Err(e) = body(layer, z_lo, &window) {
                result = Err(e);
                break;
            }
        }
        drop(sender);
        join_helper(helper, result)
    })
}

/// `result`, or the helper thread's error if `result` is fine (the caller has dropped the
/// helper's channel, so it ends). A panic in the helper is a bug: it goes on unwinding here.
fn join_helper(
    helper: Option<std::thread::ScopedJoinHandle<'_, Result<(), PagingError>>>,
    result: Result<(), PagingError>,
) -> Result<(), PagingError> {
    match helper.map(|h| h.join()) {
        Some(Err(panic)) => std::panic::resume_unwind(panic),
        Some(Ok(Err(e))) if result.is_ok() => Err(e),
        _ => result,
    }
}

/// `steps` steps of a stencil one slab deep (a 7-point stencil, FTCS), in **one** pass
/// over a field in z order: time skewing (temporal blocking along z).
///
/// Slab z of step t needs slabs z − 1, z, z + 1 of step t − 1. So as slab z_in of the
/// input arrives, slab z_in − 1 of step 1, slab z_in − 2 of step 2, …, slab z_in − t of
/// step t can be computed, each from a ring of three slabs of the step before; slab
/// z_in − `steps` of the last step is final and leaves through `write`. Every slab is read
/// once and written once per `steps` steps, and the working set is 3 · `steps` slabs (plus
/// the caller's buffers), which fits in cache for moderate slabs — so the pass is faster
/// per step than `steps` plain sweeps even in memory, and out of core it divides the
/// traffic to the backing store by `steps`.
///
/// - `read(z, slab)` fills slab z of the input (called for z = 0, 1, …, n_z − 1 in order);
/// - `write(z, slab)` takes slab z of step `steps` (in order);
/// - `step(t, z, [below, at, above], out)` computes slab z of step t (1 ≤ t ≤ `steps`)
///   from step t − 1, whose slabs are clamped at the grid's faces (`below` is slab 0 at
///   z = 0 and `above` is slab n_z − 1 at the top; a scheme with other boundaries reads z).
///
/// The result is bit for bit `steps` plain sweeps of `step`, in any order of cells: each
/// cell's arithmetic is the caller's and sees the same inputs. With `steps` = 0 the input
/// is copied.
pub fn skewed_steps(
    dims: [usize; 3],
    steps: usize,
    mut read: impl FnMut(usize, &mut [f32]) -> Result<(), PagingError>,
    mut write: impl FnMut(usize, &[f32]) -> Result<(), PagingError>,
    step: impl Fn(usize, usize, [&[f32]; 3], &mut [f32]),
) -> Result<(), PagingError> {
    let [nx, ny, nz] = dims;
    let plane = nx * ny;
    if nz == 0 || plane == 0 {
        return Ok(());
    }
    // rings[t]: slabs of step t (0 = the input) at ring positions z mod 3.
    let mut rings: Vec<Vec<f32>> = vec![vec![0.0; 3 * plane]; steps.max(1)];
    let mut last = vec![0.0f32; plane];
    let slot = |z: usize| (z % 3) * plane..(z % 3 + 1) * plane;
    for z_in in 0..nz + steps {
        if z_in < nz {
            read(z_in, &mut rings[0][slot(z_in)])?;
            if steps == 0 {
                write(z_in, &rings[0][slot(z_in)])?;
                continue;
            }
        }
        for t in 1..=steps.min(z_in) {
            let z = z_in - t;
            if z >= nz {
                continue;
            }
            let (before, after) = rings.split_at_mut(t);
            let previous = &before[t - 1];
            let inputs = [
                &previous[slot(z.saturating_sub(1))],
                &previous[slot(z)],
                &previous[slot((z + 1).min(nz - 1))],
            ];
            if t == steps {
                step(t, z, inputs, &mut last);
                write(z, &last)?;
            } else {
                step(t, z, inputs, &mut after[0][slot(z)]);
            }
        }
    }
    Ok(())
}

/// [`skewed_steps`] from one paged field into another: the input is read brick layer by
/// brick layer ([`PagedGrid::read_slabs`]) and the output written a whole brick layer at a
/// time, aprons included, from a window of slabs ([`PagedGrid::write_layer_window`]: the
/// output's bricks are overwritten, never read). Each brick of each field moves once
/// per call, whatever `steps` is.
///
/// With `prefetch`, a reader thread reads the input's next brick layer into a host buffer
/// while the pass computes (at most two layers ahead: a bounded channel), so the pass's
/// thread never waits for the store; the reads pin one brick at a time, so this needs no
/// room in the pool beyond a brick per thread (reading ahead into the pool instead needed
/// the layer read, the layer prefetched and the layer written resident together, and at
/// 1/16 of 16 layers the output's writes evicted the prefetched bricks before use). Memory:
/// up to three input layers of slabs.
///
/// Each output layer, once written, is written back to the store by a helper thread
/// ([`Pager::write_back`](crate::Pager::write_back)) while the pass goes on, so that
/// evicting its bricks later costs no I/O (when the output's pool holds a layer and a few
/// more bricks).
pub fn skewed_steps_paged(
    input: &PagedGrid,
    output: &PagedGrid,
    steps: usize,
    prefetch: bool,
    step: impl Fn(usize, usize, [&[f32]; 3], &mut [f32]),
) -> Result<(), PagingError> {
    let dims = input.geometry().dims();
    if output.geometry().dims() != dims {
        return Err(PagingError::Shape(format!(
            "skewed_steps_paged: an input of {dims:?} cells into an output of {:?}",
            output.geometry().dims()
        )));
    }
    let [nx, ny, nz] = dims;
    let plane = nx * ny;
    let b_in = input.layout().brick();
    let b_out = output.layout().brick();
    let layers_out = output.layout().bricks()[2];
    let per_layer = |field: &PagedGrid| {
        let [bx, by, _] = field.layout().bricks();
        bx * by
    };
    let layers_in = input.layout().bricks()[2];
    let layer_range = |layer: usize| (layer * b_in, ((layer + 1) * b_in).min(nz));
    // Writing behind holds one slot while the layer writes pin one per thread.
    let write_behind = output.pager().capacity() > per_layer(output) + rayon::current_num_threads();
    std::thread::scope(|scope| {
        // The reader: input layers in order, each read into its own buffer.
        let (layers, arriving) = mpsc::sync_channel::<Result<Vec<f32>, PagingError>>(1);
        let reader = prefetch.then(|| {
            scope.spawn(move || -> Result<(), PagingError> {
                for layer in 0..layers_in {
                    let (z0, z1) = layer_range(layer);
                    let mut buffer = vec![0f32; plane * (z1 - z0)];
                    let read = input.read_slabs(z0, z1, &mut buffer).map(|()| buffer);
                    let failed = read.is_err();
                    // A closed channel: the pass ended early (an error of its own).
                    if layers.send(read).is_err() || failed {
                        break;
                    }
                }
                Ok(())
            })
        });
        // The writer behind: the output's finished layers back to the store.
        let (sender, receiver) = mpsc::channel::<usize>();
        let helper = write_behind.then(|| {
            scope.spawn(move || -> Result<(), PagingError> {
                for layer in receiver {
                    let [bx, by, _] = output.layout().bricks();
                    let bricks = (0..by).flat_map(|j| (0..bx).map(move |i| (i, j)));
                    output.pager().write_back(
                        bricks.map(|(i, j)| output.pager_brick(output.layout().id([i, j, layer]))),
                    )?;
                }
                Ok(())
            })
        });
        // The input's current brick layer.
        let mut layer_in: (usize, Vec<f32>) = (usize::MAX, Vec::new());
        // The output's slabs from `out_lo` on, and the next output layer to write.
        let mut out_lo = 0;
        let mut out: Vec<f32> = Vec::with_capacity(plane * (b_out + 2));
        let mut next_layer = 0;
        let result = skewed_steps(
            dims,
            steps,
            |z, slab| {
                let layer = z / b_in;
                if layer_in.0 != layer {
                    layer_in.1 = if prefetch {
                        arriving.recv().map_err(|_| {
                            PagingError::Shape("the layer reader stopped early".into())
                        })??
                    } else {
                        let (z0, z1) = layer_range(layer);
                        let mut buffer = std::mem::take(&mut layer_in.1);
                        buffer.resize(plane * (z1 - z0), 0.0);
                        input.read_slabs(z0, z1, &mut buffer)?;
                        buffer
                    };
                    layer_in.0 = layer;
                }
                let at = (z - layer * b_in) * plane;
                slab.copy_from_slice(&layer_in.1[at..at + plane]);
                Ok(())
            },
            |z, slab| {
                debug_assert_eq!(z, out_lo + out.len() / plane);
                out.extend_from_slice(slab);
                // Write every layer whose window is complete, then keep only the slabs the
                // next layer's window starts with.
                while next_layer < layers_out {
                    let z_lo = (next_layer * b_out).saturating_sub(1);
                    let z_hi = (next_layer * b_out + b_out + 1).min(nz);
                    if z + 1 < z_hi {
                        break;
                    }
                    let window = &out[(z_lo - out_lo) * plane..(z_hi - out_lo) * plane];
                    output.write_layer_window(next_layer, z_lo, window)?;
                    if write_behind {
                        let _ = sender.send(next_layer);
                    }
                    next_layer += 1;
                    let keep = (next_layer * b_out).saturating_sub(1).clamp(out_lo, z + 1);
                    out.drain(..(keep - out_lo) * plane);
                    out_lo = keep;
                }
                Ok(())
            },
            step,
        );
        drop(arriving);
        drop(sender);
        let result = join_helper(reader, result);
        join_helper(helper, result)
    })
}
