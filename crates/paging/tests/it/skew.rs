//! Time skewing against plain sweeps: `skewed_steps` (in memory) and `skewed_steps_paged`
//! (through a pager holding a few bricks, backed by a file) give, bit for bit, the field
//! that `steps` plain sweeps of the same stencil give — on grids whose sides are not
//! multiples of the brick, down to one slab, for 0 to 6 steps; and the paged pass moves
//! each brick once whatever the number of steps.

use std::sync::Arc;

use glam::DVec3;
use lucent_grid::{BrickLayout, Grid, GridGeometry};
use lucent_paging::{
    BrickView, Eviction, FileStore, PagedGrid, Pager, PagerOptions, PagingError, skewed_steps,
    skewed_steps_paged,
};
use proptest::prelude::*;

/// A 7-point FTCS step with a source that depends on the cell and the step (so a slab
/// computed at the wrong step or place shows), neighbours clamped at the faces.
fn step_slab(dims: [usize; 3], t: usize, z: usize, slabs: [&[f32]; 3], out: &mut [f32]) {
    let [nx, ny, _] = dims;
    let [below, at, above] = slabs;
    for y in 0..ny {
        let (ym, yp) = (y.saturating_sub(1), (y + 1).min(ny - 1));
        for x in 0..nx {
            let (xm, xp) = (x.saturating_sub(1), (x + 1).min(nx - 1));
            let c = at[y * nx + x];
            let sum = (at[y * nx + xm] - c)
                + (at[y * nx + xp] - c)
                + (at[ym * nx + x] - c)
                + (at[yp * nx + x] - c)
                + (below[y * nx + x] - c)
                + (above[y * nx + x] - c);
            let q = ((x + 3 * y + 7 * z + 11 * t) % 5) as f32 * 0.01;
            out[y * nx + x] = c + 0.15 * sum - 0.02 * c + q;
        }
    }
}

/// `steps` plain sweeps over the whole field.
fn plain(dims: [usize; 3], initial: &[f32], steps: usize) -> Vec<f32> {
    let [nx, ny, nz] = dims;
    let plane = nx * ny;
    let mut a = initial.to_vec();
    let mut b = vec![0.0; a.len()];
    for t in 1..=steps {
        for z in 0..nz {
            let slab = |k: usize| &a[k * plane..(k + 1) * plane];
            let inputs = [
                slab(z.saturating_sub(1)),
                slab(z),
                slab((z + 1).min(nz - 1)),
            ];
            step_slab(dims, t, z, inputs, &mut b[z * plane..(z + 1) * plane]);
        }
        std::mem::swap(&mut a, &mut b);
    }
    a
}

fn initial(dims: [usize; 3]) -> Grid {
    let geometry = GridGeometry::new(dims, DVec3::splat(0.1), DVec3::ZERO).unwrap();
    Grid::from_fn(geometry, |p| {
        (1.0 + (9.0 * p.x).sin() * (4.0 * p.y + 3.0 * p.z).cos()) as f32
    })
}

/// Brick `id` of `field` as stored (cells and apron).
fn stored(field: &PagedGrid, id: usize) -> Vec<f32> {
    match field.brick(id).unwrap() {
        BrickView::Constant(v) => vec![v; field.layout().stored_len()],
        BrickView::Paged(pin) => pin.to_vec(),
    }
}

fn same_bits(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn in_memory_equals_plain_sweeps(
        dims in (1usize..9, 1usize..8, 1usize..13).prop_map(|(a, b, c)| [a, b, c]),
        steps in 0usize..7,
    ) {
        let field = initial(dims);
        let plane = dims[0] * dims[1];
        let mut out = vec![f32::NAN; field.data().len()];
        let mut next_read = 0;
        let mut next_write = 0;
        skewed_steps(
            dims,
            steps,
            |z, slab| {
                assert_eq!(z, next_read, "slabs are read in order");
                next_read += 1;
                slab.copy_from_slice(&field.data()[z * plane..(z + 1) * plane]);
                Ok(())
            },
            |z, slab| {
                assert_eq!(z, next_write, "slabs are written in order");
                next_write += 1;
                out[z * plane..(z + 1) * plane].copy_from_slice(slab);
                Ok(())
            },
            |t, z, slabs, o| step_slab(dims, t, z, slabs, o),
        )
        .unwrap();
        prop_assert_eq!(next_read, dims[2]);
        prop_assert_eq!(next_write, dims[2]);
        prop_assert!(same_bits(&out, &plain(dims, field.data(), steps)));
    }

    #[test]
    fn paged_equals_plain_sweeps(
        dims in (1usize..12, 1usize..10, 1usize..19).prop_map(|(a, b, c)| [a, b, c]),
        steps in 0usize..7,
        brick in 2usize..6,
        prefetch in any::<bool>(),
        eviction in prop_oneof![Just(Eviction::Lru), Just(Eviction::Nru)],
    ) {
        let field = initial(dims);
        let layout = BrickLayout::new(dims, brick).unwrap();
        // Room for one brick layer of each field being worked on, and a few more: far less
        // than the two fields once the grid is several layers deep.
        let [bx, by, _] = layout.bricks();
        let slots = (3 * bx * by + 4) as u64;
        let pager = Arc::new(
            Pager::new(
                Box::new(FileStore::create().unwrap()),
                0,
                layout.stored_len(),
                1,
                PagerOptions { budget_bytes: slots * 4 * layout.stored_len() as u64, eviction, fill: 0.0 },
            )
            .unwrap(),
        );
        let input = PagedGrid::from_grid(pager.clone(), &field, brick).unwrap();
        let output = PagedGrid::filled(pager.clone(), *field.geometry(), brick, 0.0).unwrap();
        let before = pager.stats();
        skewed_steps_paged(&input, &output, steps, prefetch, |t, z, slabs, o| {
            step_slab(dims, t, z, slabs, o)
        })
        .unwrap();
        let moved = pager.stats().since(&before);
        let result = output.to_grid().unwrap();
        let expected = plain(dims, field.data(), steps);
        prop_assert!(same_bits(result.data(), &expected));
        // Every stored value, aprons included, and every brick's range are those of the
        // expected field stored afresh: the next stencil reads consistent neighbours.
        let geometry = *field.geometry();
        let fresh = PagedGrid::from_grid(
            pager.clone(),
            &Grid::from_vec(geometry, expected).unwrap(),
            brick,
        )
        .unwrap();
        for id in 0..layout.count() {
            prop_assert!(same_bits(&stored(&output, id), &stored(&fresh, id)), "brick {id}");
            prop_assert_eq!(output.brick_range(id), fresh.brick_range(id));
        }
        // Whatever the number of steps, and with or without the reader thread, each brick
        // of the input is read from the backing store at most once, and the output's
        // bricks are overwritten, never read.
        let brick_bytes = 4 * layout.stored_len() as u64;
        prop_assert!(moved.bytes_read <= layout.count() as u64 * brick_bytes, "{moved:?}");
    }
}

#[test]
fn mismatched_fields_are_refused() {
    let a = initial([4, 4, 4]);
    let b = initial([4, 4, 5]);
    let pager = Arc::new(
        Pager::new(
            Box::new(FileStore::create().unwrap()),
            0,
            BrickLayout::new([4, 4, 5], 2).unwrap().stored_len(),
            1,
            PagerOptions {
                budget_bytes: 1 << 20,
                eviction: Eviction::Lru,
                fill: 0.0,
            },
        )
        .unwrap(),
    );
    let input = PagedGrid::from_grid(pager.clone(), &a, 2).unwrap();
    let output = PagedGrid::from_grid(pager, &b, 2).unwrap();
    let result = skewed_steps_paged(&input, &output, 2, false, |_, _, _, _| {});
    assert!(matches!(result, Err(PagingError::Shape(_))), "{result:?}");
}
