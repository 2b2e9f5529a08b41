//! The pager against a dense reference: random reads and writes of bricks under a budget
//! of a few bricks (no dirty data lost, every read sees the last write), for both eviction
//! policies, single- and multi-threaded; paged fields against dense grids (slabs, layer
//! windows, aprons, ranges); and every refusal: a budget below the working set, an
//! exhausted pool, a backing file that cannot be created, a store that fails to write.

use std::io;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use glam::DVec3;
use lucent_grid::{BrickLayout, Grid, GridGeometry};
use lucent_paging::{
    BrickStore, BrickView, Eviction, FileStore, MemoryStore, PagedGrid, Pager, PagerOptions,
    PagingError,
};
use proptest::prelude::*;

fn pager(
    store: Box<dyn BrickStore>,
    bricks: usize,
    len: usize,
    slots: u64,
    eviction: Eviction,
) -> Pager {
    Pager::new(
        store,
        bricks,
        len,
        1,
        PagerOptions {
            budget_bytes: slots * 4 * len as u64,
            eviction,
            fill: -1.0,
        },
    )
    .unwrap()
}

#[derive(Debug, Clone)]
enum Op {
    Read(usize),
    Write(usize, f32),
    Overwrite(usize, f32),
    Prefetch(usize, usize),
    Flush,
}

fn op(bricks: usize) -> impl Strategy<Value = Op> {
    prop_oneof![
        4 => (0..bricks).prop_map(Op::Read),
        4 => (0..bricks, -1e3f32..1e3).prop_map(|(b, v)| Op::Write(b, v)),
        1 => (0..bricks, -1e3f32..1e3).prop_map(|(b, v)| Op::Overwrite(b, v)),
        1 => (0..bricks, 1usize..6).prop_map(|(b, n)| Op::Prefetch(b, n)),
        1 => Just(Op::Flush),
    ]
}

/// Runs `ops` on a pager of `bricks` bricks of `T` values under a pool of `slots`, against
/// a reference: each brick written with tag t holds `value(t, i)` at index i; never written
/// ones hold `fill`. Every read must see the last write, and nothing may be lost.
fn run_ops<T: lucent_paging::Element + PartialEq>(
    bricks: usize,
    slots: u64,
    nru: bool,
    ops: &[Op],
    value: impl Fn(f32, usize) -> T,
    fill: T,
) -> Result<(), TestCaseError> {
    const LEN: usize = 27;
    let eviction = if nru { Eviction::Nru } else { Eviction::Lru };
    let size = std::mem::size_of::<T>() as u64;
    let pager = Pager::new(
        Box::new(FileStore::create().unwrap()),
        bricks,
        LEN,
        1,
        PagerOptions {
            budget_bytes: slots * size * LEN as u64,
            eviction,
            fill,
        },
    )
    .unwrap();
    let mut reference: Vec<Option<f32>> = vec![None; bricks];
    let expect = |tag: Option<f32>, i: usize| tag.map_or(fill, |t| value(t, i));
    for op in ops {
        match *op {
            Op::Read(b) => {
                let b = b % bricks;
                let pin = pager.read(b).unwrap();
                for (i, v) in pin.iter().enumerate() {
                    prop_assert!(*v == expect(reference[b], i), "brick {} value {}", b, i);
                }
            }
            Op::Write(b, tag) => {
                let b = b % bricks;
                let mut pin = pager.write(b).unwrap();
                // A partial update after reading: the old values must be there.
                for (i, v) in pin.iter_mut().enumerate() {
                    prop_assert!(*v == expect(reference[b], i));
                    *v = value(tag, i);
                }
                reference[b] = Some(tag);
            }
            Op::Overwrite(b, tag) => {
                let b = b % bricks;
                let mut pin = pager.overwrite(b).unwrap();
                for (i, v) in pin.iter_mut().enumerate() {
                    *v = value(tag, i);
                }
                reference[b] = Some(tag);
            }
            Op::Prefetch(b, n) => {
                let b = b % bricks;
                pager
                    .prefetch((b..(b + n).min(bricks)).collect::<Vec<_>>())
                    .unwrap();
            }
            Op::Flush => pager.flush().unwrap(),
        }
    }
    // Nothing lost: every brick, resident or not, holds its last write.
    for (b, tag) in reference.iter().enumerate() {
        let pin = pager.read(b).unwrap();
        for (i, v) in pin.iter().enumerate() {
            prop_assert!(*v == expect(*tag, i));
        }
    }
    let stats = pager.stats();
    prop_assert!(stats.evictions <= stats.misses + stats.prefetched);
    prop_assert!(stats.bytes_written.is_multiple_of(size * LEN as u64));
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn every_read_sees_the_last_write_under_a_budget_of_a_few_bricks(
        bricks in 3usize..40,
        slots in 1u64..5,
        nru in any::<bool>(),
        ops in proptest::collection::vec(op(40), 1..300),
    ) {
        // f32 bricks: each value is its brick's tag plus its index.
        run_ops(bricks, slots, nru, &ops, |tag: f32, i| tag + i as f32, -1.0)?;
    }

    #[test]
    fn f64_bricks_keep_every_bit(
        bricks in 3usize..40,
        slots in 1u64..5,
        nru in any::<bool>(),
        ops in proptest::collection::vec(op(40), 1..300),
    ) {
        // f64 bricks with values no f32 holds (a 10⁻¹² step): a store or a pool that went
        // through f32, or mixed up a brick's byte size, shows.
        run_ops(bricks, slots, nru, &ops, |tag: f32, i| f64::from(tag) + 1e-12 * (i + 1) as f64, -1.0)?;
    }

    #[test]
    fn paged_fields_hold_the_dense_values_their_aprons_and_ranges(
        dims in proptest::array::uniform3(1usize..23),
        brick_log2 in 1u32..4,
        slots in 4u64..12,
        nru in any::<bool>(),
        writes in proptest::collection::vec((0usize..23, 1usize..6, -5.0f32..5.0), 0..6),
    ) {
        let brick = 1 << brick_log2;
        let geometry = GridGeometry::new(dims, DVec3::splat(0.1), DVec3::ZERO).unwrap();
        let layout = BrickLayout::new(dims, brick).unwrap();
        let len = layout.stored_len();
        let eviction = if nru { Eviction::Nru } else { Eviction::Lru };
        let pager = Arc::new(pager(Box::new(FileStore::create().unwrap()), 0, len, slots, eviction));
        // Half empty space (constant bricks), half a ramp (stored bricks).
        let mut dense = Grid::from_fn(geometry, |p| if p.x < 0.5 * dims[0] as f64 * 0.1 { 0.0 } else { (p.x + 2.0 * p.y - p.z) as f32 });
        let field = PagedGrid::from_grid(pager.clone(), &dense, brick).unwrap();
        prop_assert_eq!(field.to_grid().unwrap(), dense.clone());
        let [nx, ny, nz] = dims;
        for (z0, n, v) in writes {
            let z0 = z0 % nz;
            let n = n.min(nz - z0);
            let slabs: Vec<f32> = (0..nx * ny * n).map(|i| v + (i % 7) as f32).collect();
            field.write_slabs(z0, &slabs).unwrap();
            dense.data_mut()[z0 * nx * ny..(z0 + n) * nx * ny].copy_from_slice(&slabs);
        }
        prop_assert_eq!(field.to_grid().unwrap(), dense.clone());
        let value = |c: [usize; 3]| dense.get(c[0], c[1], c[2]).unwrap();
        for id in 0..layout.count() {
            // Every stored brick equals the dense grid's, apron included.
            let stored = layout.gather(id, value);
            let view = field.brick(id).unwrap();
            let e = layout.stored_edge() as isize;
            for (s, want) in stored.iter().enumerate() {
                let local = [s as isize % e - 1, (s as isize / e) % e - 1, s as isize / (e * e) - 1];
                prop_assert_eq!(view.get(&layout, local), *want, "brick {} stored {}", id, s);
            }
            drop(view);
            let (lo, hi) = field.brick_range(id).unwrap();
            let min = stored.iter().copied().fold(f32::INFINITY, f32::min);
            let max = stored.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            prop_assert_eq!((lo, hi), (min, max));
        }
        // Planes across every axis read back as the dense grid's, and a plane written
        // across x or y keeps every apron current too.
        for axis in 0..3 {
            let (b, d) = ((axis + 1) % 3, (axis + 2) % 3);
            let at = |index: usize, local: usize| {
                let mut c = [0; 3];
                c[axis] = index;
                c[b] = local % dims[b];
                c[d] = local / dims[b];
                c
            };
            let index = dims[axis] / 2;
            let mut plane = vec![0.0; dims[b] * dims[d]];
            field.read_plane(axis, index, &mut plane).unwrap();
            for (local, v) in plane.iter().enumerate() {
                let c = at(index, local);
                prop_assert_eq!(*v, dense.get(c[0], c[1], c[2]).unwrap());
            }
            let fresh: Vec<f32> = (0..plane.len()).map(|i| 100.0 * axis as f32 + i as f32).collect();
            field.write_plane(axis, index, &fresh).unwrap();
            for (local, v) in fresh.iter().enumerate() {
                let c = at(index, local);
                dense.data_mut()[geometry.index(c[0], c[1], c[2])] = *v;
            }
        }
        prop_assert_eq!(field.to_grid().unwrap(), dense.clone());
        let value = |c: [usize; 3]| dense.get(c[0], c[1], c[2]).unwrap();
        for id in 0..layout.count() {
            let stored = layout.gather(id, value);
            let view = field.brick(id).unwrap();
            let e = layout.stored_edge() as isize;
            for (s, want) in stored.iter().enumerate() {
                let local = [s as isize % e - 1, (s as isize / e) % e - 1, s as isize / (e * e) - 1];
                prop_assert_eq!(view.get(&layout, local), *want, "after planes: brick {} stored {}", id, s);
            }
        }
        // Each layer's window is the dense slabs around it.
        for layer in 0..layout.bricks()[2] {
            let (z_lo, window) = field.read_layer_window(layer).unwrap();
            let start = z_lo * nx * ny;
            prop_assert_eq!(&window[..], &dense.data()[start..start + window.len()]);
            prop_assert_eq!(z_lo, (layer * brick).saturating_sub(1));
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn line_integrals_through_paged_fields_are_the_dense_ones_bit_for_bit(
        dims in proptest::array::uniform3(1usize..20),
        brick_log2 in 1u32..4,
        ends in proptest::array::uniform6(-0.5f64..2.5),
        slots in 1u64..4,
    ) {
        // Any segment (inside, crossing, outside the box), bricks of 2 to 8 cells, a pool
        // of 1 to 3 bricks: the walk pins one brick at a time and reads the same values.
        let brick = 1 << brick_log2;
        let geometry = GridGeometry::new(dims, DVec3::new(0.1, 0.13, 0.08), DVec3::ZERO).unwrap();
        let layout = BrickLayout::new(dims, brick).unwrap();
        let len = layout.stored_len();
        let pager = Arc::new(pager(Box::new(MemoryStore::default()), 0, len, slots, Eviction::Lru));
        let dense = Grid::from_fn(geometry, |p| {
            if p.y < 0.5 { 0.0 } else { (1.0 + 3.0 * (4.0 * p.x).sin() * (3.0 * p.z).cos()).abs() as f32 }
        });
        let field = PagedGrid::from_grid(pager, &dense, brick).unwrap();
        let (lo, hi) = geometry.bounds();
        let size = hi - lo;
        let a = lo + size * DVec3::new(ends[0], ends[1], ends[2]);
        let b = lo + size * DVec3::new(ends[3], ends[4], ends[5]);
        for cutoff in [f64::INFINITY, 0.3] {
            let want = dense.line_integral(a, b, cutoff);
            let got = field.line_integral(a, b, cutoff).unwrap();
            prop_assert_eq!(got.to_bits(), want.to_bits(), "{} vs {}", got, want);
        }
    }
}

#[test]
fn threads_writing_their_own_bricks_lose_nothing() {
    const LEN: usize = 64;
    let bricks = 48;
    let pager = pager(
        Box::new(FileStore::create().unwrap()),
        bricks,
        LEN,
        6,
        Eviction::Nru,
    );
    std::thread::scope(|scope| {
        for t in 0..4 {
            let pager = &pager;
            scope.spawn(move || {
                for round in 0..50u32 {
                    for b in (t..bricks).step_by(4) {
                        let mut pin = pager.write(b).unwrap();
                        for (i, v) in pin.iter_mut().enumerate() {
                            // Each round adds one to what the last round left.
                            let before = if round == 0 { 0.0 } else { *v };
                            assert_eq!(before, round as f32 * (b * LEN + i) as f32 / 1e3);
                            *v = (round + 1) as f32 * (b * LEN + i) as f32 / 1e3;
                        }
                    }
                }
            });
        }
    });
    for b in 0..bricks {
        let pin = pager.read(b).unwrap();
        for (i, v) in pin.iter().enumerate() {
            assert_eq!(*v, 50.0 * (b * LEN + i) as f32 / 1e3);
        }
    }
    assert!(pager.stats().write_backs > 0);
}

#[test]
fn writing_behind_while_threads_write_loses_nothing() {
    // Four writers update their bricks round after round while a fifth thread writes
    // every brick back over and over (its I/O outside the pager's lock). A brick written
    // back while a writer has it pinned, or pins it meanwhile, must stay dirty: otherwise
    // its eviction would drop the writer's update and a later round would see old values.
    const LEN: usize = 64;
    let bricks = 48;
    for eviction in [Eviction::Lru, Eviction::Nru] {
        let pager = pager(
            Box::new(FileStore::create().unwrap()),
            bricks,
            LEN,
            6,
            eviction,
        );
        let writers_done = AtomicBool::new(false);
        std::thread::scope(|scope| {
            let writers: Vec<_> = (0..4)
                .map(|t| {
                    let pager = &pager;
                    scope.spawn(move || {
                        for round in 0..50u32 {
                            for b in (t..bricks).step_by(4) {
                                let mut pin = pager.write(b).unwrap();
                                for (i, v) in pin.iter_mut().enumerate() {
                                    let before = if round == 0 { 0.0 } else { *v };
                                    assert_eq!(before, round as f32 * (b * LEN + i) as f32 / 1e3);
                                    *v = (round + 1) as f32 * (b * LEN + i) as f32 / 1e3;
                                }
                            }
                        }
                    })
                })
                .collect();
            let behind = scope.spawn(|| {
                while !writers_done.load(Ordering::Acquire) {
                    pager.write_back(0..bricks).unwrap();
                }
            });
            // Joined before any unwrap: a failing writer must not leave the writer-behind
            // looping (the scope would wait for it forever).
            let results: Vec<_> = writers.into_iter().map(|w| w.join()).collect();
            writers_done.store(true, Ordering::Release);
            behind.join().unwrap();
            for r in results {
                r.unwrap();
            }
        });
        for b in 0..bricks {
            let pin = pager.read(b).unwrap();
            for (i, v) in pin.iter().enumerate() {
                assert_eq!(*v, 50.0 * (b * LEN + i) as f32 / 1e3, "{eviction:?}");
            }
        }
        assert!(pager.stats().write_backs > 0);
    }
}

#[test]
fn both_policies_keep_a_hot_brick_through_a_scan() {
    // Brick 0 is read between every two reads of a scan over bricks 1–5, with 4 slots.
    // LRU keeps the hot brick resident (one miss, then 49 hits) while the scan of five
    // bricks through the three other slots misses every time. The clock approximates it:
    // when every slot's bit is set, one turn clears them all and the hand may come back
    // to the hot brick first (second chance degrading to FIFO) — here once in 50.
    for eviction in [Eviction::Lru, Eviction::Nru] {
        let pager = pager(Box::new(MemoryStore::default()), 6, 8, 4, eviction);
        for _ in 0..10 {
            for b in 1..6 {
                drop(pager.read(0).unwrap());
                drop(pager.read(b).unwrap());
            }
        }
        assert!(pager.is_resident(0), "{eviction:?} evicted the hot brick");
        let stats = pager.stats();
        assert_eq!(stats.hits + stats.misses, 100);
        match eviction {
            Eviction::Lru => assert_eq!(stats.hits, 49, "{stats:?}"),
            Eviction::Nru => assert!((45..=49).contains(&stats.hits), "{stats:?}"),
        }
    }
}

#[test]
fn a_budget_below_the_working_set_is_refused_before_anything_is_allocated() {
    let err = Pager::new(
        Box::new(MemoryStore::default()),
        1 << 30,
        1000,
        8,
        PagerOptions {
            budget_bytes: 7 * 4000,
            eviction: Eviction::Lru,
            fill: 0.0f32,
        },
    )
    .unwrap_err();
    match err {
        PagingError::BudgetTooSmall { budget, needed, .. } => {
            assert_eq!((budget, needed), (28_000, 32_000));
        }
        other => panic!("{other}"),
    }
}

#[test]
fn pinning_more_bricks_than_the_pool_holds_is_an_error_not_a_hang() {
    let pager = pager(Box::new(MemoryStore::default()), 8, 4, 3, Eviction::Nru);
    let pins: Vec<_> = (0..3).map(|b| pager.read(b).unwrap()).collect();
    assert!(matches!(
        pager.read(3),
        Err(PagingError::PoolExhausted { slots: 3 })
    ));
    drop(pins);
    assert!(pager.read(3).is_ok());
    assert!(matches!(
        pager.read(8),
        Err(PagingError::NoSuchBrick { brick: 8, count: 8 })
    ));
}

#[test]
fn a_backing_file_that_cannot_be_created_is_an_error() {
    let missing = std::env::temp_dir().join("lucent-no-such-folder/deeper");
    match FileStore::create_in(&missing) {
        Err(e @ PagingError::Create { .. }) => {
            assert!(e.to_string().contains("lucent-no-such-folder"), "{e}")
        }
        other => panic!("{other:?}"),
    }
}

/// A store whose writes fail while `full` is set, like a full disk.
#[derive(Debug, Default)]
struct FlakyStore {
    inner: MemoryStore,
    full: AtomicBool,
}

impl BrickStore for FlakyStore {
    fn read(&self, brick: usize, out: &mut [u8]) -> io::Result<()> {
        self.inner.read(brick, out)
    }
    fn write(&self, brick: usize, data: &[u8]) -> io::Result<()> {
        if self.full.load(Ordering::Relaxed) {
            return Err(io::Error::new(
                io::ErrorKind::StorageFull,
                "no space left on device",
            ));
        }
        self.inner.write(brick, data)
    }
    fn describe(&self) -> String {
        "a flaky store".into()
    }
}

#[test]
fn a_failing_write_back_is_an_error_and_loses_nothing() {
    let store = Arc::new(FlakyStore::default());
    #[derive(Debug)]
    struct Shared(Arc<FlakyStore>);
    impl BrickStore for Shared {
        fn read(&self, b: usize, out: &mut [u8]) -> io::Result<()> {
            self.0.read(b, out)
        }
        fn write(&self, b: usize, data: &[u8]) -> io::Result<()> {
            self.0.write(b, data)
        }
        fn describe(&self) -> String {
            self.0.describe()
        }
    }
    for eviction in [Eviction::Lru, Eviction::Nru] {
        let pager = pager(Box::new(Shared(store.clone())), 6, 16, 2, eviction);
        for b in 0..2 {
            pager.write(b).unwrap().fill(b as f32 + 10.0);
        }
        store.full.store(true, Ordering::Relaxed);
        // Loading a third brick must evict a dirty one, whose write-back fails.
        let err = pager.read(2).unwrap_err();
        assert!(
            matches!(
                err,
                PagingError::Io {
                    action: "writing",
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("no space left"), "{err}");
        assert!(pager.flush().is_err());
        // The disk has room again: everything is still there.
        store.full.store(false, Ordering::Relaxed);
        for b in 0..2 {
            assert!(pager.read(b).unwrap().iter().all(|&v| v == b as f32 + 10.0));
        }
        assert!(pager.read(2).unwrap().iter().all(|&v| v == -1.0));
        for b in 0..2 {
            assert!(pager.read(b).unwrap().iter().all(|&v| v == b as f32 + 10.0));
        }
    }
}

#[test]
fn sparse_fields_store_only_their_dense_bricks() {
    let geometry = GridGeometry::new([64, 64, 64], DVec3::splat(1.0 / 64.0), DVec3::ZERO).unwrap();
    let layout = BrickLayout::new(geometry.dims(), 8).unwrap();
    let pager = Arc::new(pager(
        Box::new(MemoryStore::default()),
        0,
        layout.stored_len(),
        8,
        Eviction::Lru,
    ));
    // A ball of radius 0.2 in the unit box: most bricks are empty.
    let ball = Grid::from_fn(geometry, |p| {
        if (p - DVec3::splat(0.5)).length() < 0.2 {
            1.0 + p.x as f32
        } else {
            0.0
        }
    });
    let field = PagedGrid::from_grid(pager.clone(), &ball, 8).unwrap();
    let stored = field.stored_bricks();
    assert!(
        stored > 0 && stored < layout.count() / 4,
        "{stored} of {}",
        layout.count()
    );
    assert_eq!(field.to_grid().unwrap(), ball);
    // An empty brick far from the ball reads as its constant without touching the pager.
    assert!(matches!(field.brick(0).unwrap(), BrickView::Constant(0.0)));
    // Its range is zero, the ball's bricks bound the ball.
    assert_eq!(field.brick_range(0), Some((0.0, 0.0)));
    assert_eq!(field.brick_range(layout.count()), None);
    assert!(field.max_over_cells([0; 3], [63; 3]) >= 1.5);
}

#[test]
fn reads_and_writes_that_do_not_fit_the_field_are_errors() {
    let geometry = GridGeometry::new([9, 7, 5], DVec3::splat(0.1), DVec3::ZERO).unwrap();
    let layout = BrickLayout::new(geometry.dims(), 4).unwrap();
    let pager = Arc::new(pager(
        Box::new(MemoryStore::default()),
        0,
        layout.stored_len(),
        4,
        Eviction::Lru,
    ));
    let field = PagedGrid::filled(pager, geometry, 4, 1.0).unwrap();
    let shape = |r: Result<(), PagingError>| matches!(r, Err(PagingError::Shape(_)));
    assert!(shape(field.get([9, 0, 0]).map(|_| ())));
    assert!(shape(field.read_slabs(3, 2, &mut [])));
    assert!(shape(field.read_slabs(0, 6, &mut vec![0.0; 9 * 7 * 6])));
    assert!(shape(field.read_slabs(0, 1, &mut [0.0; 5])));
    assert!(shape(field.read_layer_window(2).map(|_| ())));
    assert!(shape(field.write_slabs(4, &vec![0.0; 2 * 9 * 7])));
    assert!(shape(field.write_slabs(0, &[0.0; 10])));
    assert!(shape(field.read_plane(3, 0, &mut [])));
    assert!(shape(field.read_plane(0, 9, &mut [0.0; 35])));
    assert!(shape(field.write_plane(1, 0, &[0.0; 3])));
    assert!(matches!(
        field.brick(layout.count()),
        Err(PagingError::NoSuchBrick { .. })
    ));
    // The field is untouched.
    assert!(field.to_grid().unwrap().data().iter().all(|&v| v == 1.0));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn trilinear_samples_of_paged_fields_are_the_dense_ones_bit_for_bit(
        dims in proptest::array::uniform3(1usize..14),
        brick_log2 in 0u32..4,
        points in proptest::collection::vec(proptest::array::uniform3(-0.3f64..1.3), 1..64),
        slots in 1u64..3,
    ) {
        // Points inside and outside the box (clamped), axes of one cell, bricks of 1 to 8
        // cells, constant bricks (the lower half is 0): the values and blend are the dense
        // grid's.
        let brick = 1 << brick_log2;
        let geometry = GridGeometry::new(dims, DVec3::new(0.1, 0.13, 0.08), DVec3::ZERO).unwrap();
        let layout = BrickLayout::new(dims, brick).unwrap();
        let pager = Arc::new(pager(Box::new(MemoryStore::default()), 0, layout.stored_len(), slots, Eviction::Nru));
        let dense = Grid::from_fn(geometry, |p| {
            if p.z < 0.4 { 0.0 } else { (0.5 + (7.0 * p.x).sin() * (5.0 * p.y).cos()).abs() as f32 }
        });
        let field = PagedGrid::from_grid(pager, &dense, brick).unwrap();
        let (lo, hi) = geometry.bounds();
        let mut sampler = field.sampler();
        for p in points {
            let x = lo + (hi - lo) * DVec3::from_array(p);
            let want = dense.sample_trilinear(x);
            let got = sampler.sample_trilinear(x).unwrap();
            prop_assert_eq!(got.to_bits(), want.to_bits(), "at {:?}: {} vs {}", x, got, want);
        }
    }
}

#[test]
fn discarded_bricks_read_as_the_fill_and_free_their_slots() {
    let store = Box::new(FileStore::create().unwrap());
    let pager = pager(store, 4, 8, 2, Eviction::Lru);
    for b in 0..4 {
        pager.write(b).unwrap().fill(b as f32);
    }
    // Bricks 0 and 1 were evicted to the file, 2 and 3 are resident.
    assert!(!pager.is_resident(0) && pager.is_resident(3));
    let pin = pager.read(3).unwrap();
    assert!(matches!(
        pager.discard(3),
        Err(PagingError::Pinned { brick: 3 })
    ));
    drop(pin);
    for b in [0, 3] {
        pager.discard(b).unwrap();
        assert!(pager.is_fresh(b));
        assert_eq!(
            *pager.read(b).unwrap(),
            vec![-1.0; 8],
            "brick {b} reads as the fill"
        );
    }
    // The other bricks keep their values.
    assert_eq!(*pager.read(2).unwrap(), vec![2.0; 8]);
    assert_eq!(*pager.read(1).unwrap(), vec![1.0; 8]);
    assert!(!pager.is_fresh(1));
}
