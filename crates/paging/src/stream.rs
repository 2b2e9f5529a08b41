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
        if let Some(helper) = helper {
            match helper.join() {
                Ok(Err(e)) if result.is_ok() => result = Err(e),
                Ok(_) => {}
                // A panic in the helper is a bug: it goes on unwinding here.
                Err(panic) => std::panic::resume_unwind(panic),
            }
        }
        result
    })
}
