//! `Grid::line_integral` against adaptive quadrature of the same trilinear field.

use glam::DVec3;
use lucent_grid::{EmptyBricks, Grid, GridGeometry};
use proptest::prelude::*;

fn reference(grid: &Grid, a: DVec3, b: DVec3) -> f64 {
    // Adaptive quadrature of the clamped trilinear interpolant, zero outside the box.
    let (lo, hi) = grid.geometry().bounds();
    // Clip to the box first, so that the integrand has no jump.
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for axis in 0..3 {
        let d = b[axis] - a[axis];
        if d == 0.0 {
            if a[axis] < lo[axis] || a[axis] > hi[axis] {
                return 0.0;
            }
        } else {
            let (ta, tb) = ((lo[axis] - a[axis]) / d, (hi[axis] - a[axis]) / d);
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
    }
    if t0 >= t1 {
        return 0.0;
    }
    let (a, b) = (a + (b - a) * t0, a + (b - a) * t1);
    let length = (b - a).length();
    // Composite Simpson on 2·10⁴ panels: the interpolant's kinks at cell-centre planes cost
    // O(panel²) each, far below the tolerance.
    let n = 20_000;
    let f = |t: f64| {
        let p = a + (b - a) * t;
        f64::from(grid.sample_trilinear(p)) * length
    };
    let dt = 1.0 / n as f64;
    (0..n)
        .map(|i| {
            let t = i as f64 * dt;
            dt / 6.0 * (f(t) + 4.0 * f(t + 0.5 * dt) + f(t + dt))
        })
        .sum()
}

proptest! {
    #[test]
    fn line_integral_matches_quadrature_of_the_trilinear_field(
        dims in [1usize..9, 1usize..9, 1usize..9],
        h in [0.2f64..2.0, 0.2f64..2.0, 0.2f64..2.0],
        a in [-3.0f64..12.0, -3.0f64..12.0, -3.0f64..12.0],
        b in [-3.0f64..12.0, -3.0f64..12.0, -3.0f64..12.0],
        seed in 0u64..1000,
    ) {
        let geometry = GridGeometry::new(dims, DVec3::from_array(h), DVec3::ZERO).unwrap();
        let grid = Grid::from_fn(geometry, |p| (1.0 + (p.x * 1.3 + seed as f64).sin() * (p.y * 0.7).cos() + 0.1 * p.z) as f32);
        let (a, b) = (DVec3::from_array(a), DVec3::from_array(b));
        let exact = reference(&grid, a, b);
        let got = grid.line_integral(a, b, f64::INFINITY);
        // The reference is good to ~1e-8 (kinks, and the box edge where the integrand
        // jumps); the walker itself is exact to round-off.
        prop_assert!((got - exact).abs() < 1e-8 * (1.0 + exact.abs()), "got {got}, quadrature {exact}");
    }
}

#[test]
fn axis_aligned_segments_on_cell_planes() {
    let geometry = GridGeometry::new([4, 4, 4], DVec3::ONE, DVec3::ZERO).unwrap();
    let grid = Grid::from_fn(geometry, |p| p.x as f32);
    // Along x at a height exactly on a cell-centre plane and on a cell face.
    for y in [0.5, 1.0, 2.5, 4.0] {
        let got = grid.line_integral(
            DVec3::new(-1.0, y, 1.5),
            DVec3::new(5.0, y, 1.5),
            f64::INFINITY,
        );
        // σ = x between 0.5 and 3.5, clamped to 0.5 and 3.5 outside: 0.25 + 6 + 1.75.
        assert!((got - 8.0).abs() < 1e-12, "y = {y}: {got}");
    }
    assert_eq!(
        grid.line_integral(
            DVec3::new(5.0, 5.0, 5.0),
            DVec3::new(6.0, 7.0, 8.0),
            f64::INFINITY
        ),
        0.0
    );
}

proptest! {
    #[test]
    fn traversal_lengths_add_up_to_the_clipped_segment_and_match_nearest_sampling(
        dims in [1usize..7, 1usize..7, 1usize..7],
        h in [0.3f64..2.0, 0.3f64..2.0, 0.3f64..2.0],
        a in [-3.0f64..10.0, -3.0f64..10.0, -3.0f64..10.0],
        b in [-3.0f64..10.0, -3.0f64..10.0, -3.0f64..10.0],
    ) {
        let geometry = GridGeometry::new(dims, DVec3::from_array(h), DVec3::ZERO).unwrap();
        let (a, b) = (DVec3::from_array(a), DVec3::from_array(b));
        let mut per_cell = vec![0.0f64; geometry.voxel_count()];
        geometry.traverse(a, b, |i, enter, exit| {
            per_cell[i] += exit - enter;
            true
        });
        // Reference: midpoint sampling of the cell index along the segment.
        let n = 20_000;
        let (lo, hi) = geometry.bounds();
        let mut reference = vec![0.0f64; geometry.voxel_count()];
        let dl = (b - a).length() / n as f64;
        for s in 0..n {
            let p = a + (b - a) * ((s as f64 + 0.5) / n as f64);
            if p.cmpge(lo).all() && p.cmplt(hi).all() {
                let c = ((p - lo) / geometry.spacing()).floor();
                let idx = geometry.index(c.x as usize, c.y as usize, c.z as usize);
                reference[idx] += dl;
            }
        }
        for (got, want) in per_cell.iter().zip(&reference) {
            // Each cell boundary misplaces at most one sample of length dl.
            prop_assert!((got - want).abs() <= 2.0 * dl + 1e-12, "{got} vs {want}");
        }
    }
}

/// A sparse field: zero except in a few balls, so that whole bricks are empty.
fn sparse(geometry: GridGeometry, seed: u64) -> Grid {
    let (lo, hi) = geometry.bounds();
    let size = hi - lo;
    let centre = |k: u64| {
        let f = |s: u64| ((seed * 7919 + k * 104_729 + s * 31) % 1000) as f64 / 1000.0;
        lo + size * DVec3::new(f(1), f(2), f(3))
    };
    let balls: Vec<DVec3> = (0..3).map(centre).collect();
    let radius = 0.2 * size.min_element().max(1e-9);
    Grid::from_fn(geometry, |p| {
        balls
            .iter()
            .map(|c| ((radius - (p - *c).length()) / radius).max(0.0) * 5.0)
            .sum::<f64>() as f32
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn skipping_empty_bricks_keeps_every_bit(
        dims in [1usize..24, 1usize..24, 1usize..24],
        brick in 1usize..9,
        // Endpoints on a coarse lattice of quarter cells make crossings tie (segments
        // through cell corners and along diagonals), where the walk's order matters.
        a in [-8i32..104, -8i32..104, -8i32..104],
        b in [-8i32..104, -8i32..104, -8i32..104],
        quarter in proptest::bool::ANY,
        seed in 0u64..1000,
    ) {
        let geometry = GridGeometry::new(dims, DVec3::new(0.5, 0.25, 0.5), DVec3::ZERO).unwrap();
        let grid = sparse(geometry, seed);
        let empty = EmptyBricks::of(&grid, brick).unwrap();
        let scale = if quarter { 0.125 } else { 0.1 + 0.013 * (seed % 7) as f64 };
        let (a, b) = (
            DVec3::from_array(a.map(f64::from)) * scale,
            DVec3::from_array(b.map(f64::from)) * scale,
        );
        for cutoff in [f64::INFINITY, 1.0] {
            let want = grid.line_integral(a, b, cutoff);
            let got = grid.line_integral_skipping(&empty, a, b, cutoff);
            prop_assert_eq!(got.to_bits(), want.to_bits(), "{} against {}", got, want);
        }
    }
}

#[test]
fn a_mask_marks_exactly_the_bricks_whose_dual_cells_are_zero() {
    // One non-zero cell at (4, 4, 4) on 8³ cells in 2³ bricks: the dual cells reading it
    // have lower corners (3..=4)³, in bricks (1..=2)³, so 8 of 64 bricks are not empty.
    let geometry = GridGeometry::new([8; 3], DVec3::ONE, DVec3::ZERO).unwrap();
    let mut grid = Grid::filled(geometry, 0.0);
    grid.set(4, 4, 4, 1.0);
    let empty = EmptyBricks::of(&grid, 2).unwrap();
    assert_eq!(empty.empty_fraction(), 56.0 / 64.0);
    for (cell, want) in [
        ([3, 3, 3], false),
        ([4, 4, 4], false),
        ([2, 2, 2], false),
        ([1, 1, 1], true),
        ([6, 6, 6], true),
    ] {
        assert_eq!(empty.region(cell).1, want, "{cell:?}");
    }
}
