//! Dense-grid sampling, the multigrid transfer operators, resampling and the bricked grid.

use glam::DVec3;
use lucent_grid::procedural::NoiseCloud;
use lucent_grid::resample::{prolong_constant, prolong_trilinear, resample, restrict};
use lucent_grid::{BrickedGrid, Grid, GridGeometry};
use proptest::prelude::*;

fn geometry_strategy(max_dim: usize) -> impl Strategy<Value = GridGeometry> {
    geometry_from(1, max_dim)
}

fn geometry_from(min_dim: usize, max_dim: usize) -> impl Strategy<Value = GridGeometry> {
    (
        [min_dim..=max_dim, min_dim..=max_dim, min_dim..=max_dim],
        [0.1f64..3.0, 0.1f64..3.0, 0.1f64..3.0],
        [-5.0f64..5.0, -5.0f64..5.0, -5.0f64..5.0],
    )
        .prop_map(|(d, h, o)| {
            GridGeometry::new(d, DVec3::from_array(h), DVec3::from_array(o)).unwrap()
        })
}

/// A linear field a·p + b with coefficients of order one.
fn linear_strategy() -> impl Strategy<Value = (DVec3, f64)> {
    ([-2.0f64..2.0, -2.0f64..2.0, -2.0f64..2.0], -3.0f64..3.0)
        .prop_map(|(a, b)| (DVec3::from_array(a), b))
}

/// f32 storage rounds each value by 2⁻²⁴ relative; interpolation adds a few more roundings.
fn f32_tolerance(scale: f64) -> f64 {
    1e-6 * scale.max(1.0)
}

proptest! {
    #[test]
    fn trilinear_sampling_reproduces_linear_fields(
        geometry in geometry_strategy(12),
        (a, b) in linear_strategy(),
        t in [0.0f64..1.0, 0.0f64..1.0, 0.0f64..1.0],
    ) {
        let field = |p: DVec3| a.dot(p) + b;
        let grid = Grid::from_fn(geometry, |p| field(p) as f32);
        // Any point between the first and last cell centres (where no clamping happens).
        let first = geometry.cell_centre(0, 0, 0);
        let [nx, ny, nz] = geometry.dims();
        let last = geometry.cell_centre(nx - 1, ny - 1, nz - 1);
        let p = first + (last - first) * DVec3::from_array(t);
        let scale = a.abs().dot(first.abs().max(last.abs())) + b.abs();
        prop_assert!((f64::from(grid.sample_trilinear(p)) - field(p)).abs() <= f32_tolerance(scale));
        // Outside, clamping returns the value at the nearest point of the centre box.
        let outside = last + DVec3::new(1.0, 2.0, 3.0);
        prop_assert!((f64::from(grid.sample_trilinear(outside)) - field(last)).abs() <= f32_tolerance(scale));
    }

    #[test]
    fn restriction_undoes_constant_prolongation_exactly(
        geometry in geometry_strategy(9),
        seed in any::<u64>(),
    ) {
        let coarse = Grid::from_fn(geometry, |p| ((p.x * 7.1 + p.y * 3.3 - p.z + seed as f64 * 1e-3).sin() * 5.0) as f32);
        let fine_geometry = GridGeometry::new(geometry.dims().map(|n| 2 * n), geometry.spacing() / 2.0, geometry.origin()).unwrap();
        let fine = prolong_constant(&coarse, fine_geometry).unwrap();
        // The mean of eight equal f32 values, computed in f64, is that value exactly.
        let back = restrict(&fine);
        prop_assert_eq!(back.data(), coarse.data());
    }

    #[test]
    fn trilinear_prolongation_reproduces_linear_fields_and_restriction_returns_them(
        // Two coarse cells per axis at least: one cell carries no slope to reproduce.
        geometry in geometry_from(2, 7),
        (a, b) in linear_strategy(),
    ) {
        let field = |p: DVec3| a.dot(p) + b;
        let coarse = Grid::from_fn(geometry, |p| field(p) as f32);
        let fine_geometry = GridGeometry::new(geometry.dims().map(|n| 2 * n), geometry.spacing() / 2.0, geometry.origin()).unwrap();
        let fine = prolong_trilinear(&coarse, fine_geometry).unwrap();
        let (lo, hi) = fine_geometry.bounds();
        let scale = a.abs().dot(lo.abs().max(hi.abs())) + b.abs();
        let [fx, fy, fz] = fine_geometry.dims();
        for k in 0..fz {
            for j in 0..fy {
                for i in 0..fx {
                    let exact = field(fine_geometry.cell_centre(i, j, k));
                    prop_assert!((f64::from(fine.get(i, j, k).unwrap()) - exact).abs() <= 4.0 * f32_tolerance(scale));
                }
            }
        }
        let back = restrict(&fine);
        for (r, c) in back.data().iter().zip(coarse.data()) {
            prop_assert!((f64::from(*r) - f64::from(*c)).abs() <= 4.0 * f32_tolerance(scale));
        }
    }

    #[test]
    fn bricked_grid_returns_exactly_the_dense_values(
        geometry in geometry_strategy(30),
        brick_log2 in 0u32..5,
        seed in any::<u64>(),
    ) {
        // Sparse content: a ball of noise in an empty box, so that both kinds of brick occur.
        let (lo, hi) = geometry.bounds();
        let cloud = NoiseCloud::new(seed, 0.5 * (lo + hi), 0.3 * (hi - lo).max_element());
        let dense = cloud.rasterize(geometry).unwrap();
        let bricks = BrickedGrid::from_dense(&dense, 1 << brick_log2).unwrap();
        let [nx, ny, nz] = geometry.dims();
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let v = dense.get(i, j, k).unwrap();
                    prop_assert_eq!(bricks.get(i, j, k).map(f32::to_bits), Some(v.to_bits()));
                    let b = bricks.brick_size();
                    let (min, max) = bricks.brick_range(i / b, j / b, k / b).unwrap();
                    prop_assert!(min <= v && v <= max);
                }
            }
        }
        prop_assert_eq!(bricks.get(nx, 0, 0), None);
        prop_assert_eq!(bricks.to_dense(), dense.clone());
        // The majorant grid bounds every value of its brick.
        let majorant = bricks.majorant_grid();
        prop_assert_eq!(majorant.dims(), bricks.brick_dims());
        let b = bricks.brick_size();
        for (index, &v) in dense.data().iter().enumerate() {
            let [i, j, k] = geometry.coords(index);
            prop_assert!(majorant.get(i / b, j / b, k / b).unwrap() >= v);
        }
    }

    #[test]
    fn max_over_a_box_bounds_the_trilinear_interpolant_in_it(
        geometry in geometry_strategy(30),
        brick_log2 in 0u32..5,
        seed in any::<u64>(),
        corners in proptest::array::uniform6(-0.2f64..1.2),
        along in proptest::array::uniform3(0.0f64..1.0),
    ) {
        // A box anywhere (partly or wholly outside the grid too) and a point in it: the
        // interpolant there never exceeds the bound, which is the sharpest brick-level one:
        // the maximum over the bricks the box touches, aprons included. Near a brick's face
        // the interpolant blends in the neighbour brick, which only the apron covers.
        let (lo, hi) = geometry.bounds();
        let cloud = NoiseCloud::new(seed, 0.5 * (lo + hi), 0.3 * (hi - lo).max_element());
        let dense = cloud.rasterize(geometry).unwrap();
        let bricks = BrickedGrid::from_dense(&dense, 1 << brick_log2).unwrap();
        let size = hi - lo;
        let a = lo + size * DVec3::new(corners[0], corners[1], corners[2]);
        let c = lo + size * DVec3::new(corners[3], corners[4], corners[5]);
        let p = a.min(c) + (a.max(c) - a.min(c)) * DVec3::from_array(along);
        let bound = bricks.max_over(a, c);
        prop_assert!(dense.sample_trilinear(p) <= bound, "{} > {bound}", dense.sample_trilinear(p));
        // The whole grid's box bounds everything, and equals the largest value.
        prop_assert_eq!(bricks.max_over(lo, hi), dense.stats().max);
    }
}

#[test]
fn restriction_conserves_the_integral_on_even_grids() {
    let geometry = GridGeometry::new(
        [16, 8, 12],
        DVec3::new(0.5, 1.0, 0.25),
        DVec3::new(-1.0, 2.0, 0.0),
    )
    .unwrap();
    let fine = Grid::from_fn(geometry, |p| (p.x * p.y - p.z * p.z).exp() as f32);
    let coarse = restrict(&fine);
    let integral = |g: &Grid| g.sum() * g.geometry().cell_volume();
    assert_eq!(coarse.dims(), [8, 4, 6]);
    // Each coarse value is computed in f64 and rounded once to f32: relative 6e-8 per cell.
    assert!((integral(&coarse) - integral(&fine)).abs() <= 1e-6 * integral(&fine).abs());
}

#[test]
fn odd_axes_restrict_to_the_cells_that_exist() {
    let geometry = GridGeometry::new([3, 1, 1], DVec3::ONE, DVec3::ZERO).unwrap();
    let fine = Grid::from_vec(geometry, vec![1.0, 3.0, 10.0]).unwrap();
    let coarse = restrict(&fine);
    assert_eq!(coarse.data(), &[2.0, 10.0]);
    assert!(
        prolong_constant(
            &coarse,
            GridGeometry::new([5, 1, 1], DVec3::ONE, DVec3::ONE).unwrap()
        )
        .is_err()
    );
}

#[test]
fn downsampling_by_an_integer_factor_averages_and_keeps_linear_fields() {
    let geometry = GridGeometry::new([12, 12, 12], DVec3::splat(0.25), DVec3::ZERO).unwrap();
    let linear = Grid::from_fn(geometry, |p| {
        (1.5 * p.x - 0.5 * p.y + 2.0 * p.z + 1.0) as f32
    });
    let coarse = resample(&linear, [4, 6, 3]).unwrap();
    let [nx, ny, nz] = coarse.dims();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let p = coarse.geometry().cell_centre(i, j, k);
                let exact = 1.5 * p.x - 0.5 * p.y + 2.0 * p.z + 1.0;
                assert!(
                    (f64::from(coarse.get(i, j, k).unwrap()) - exact).abs() < 1e-5,
                    "({i},{j},{k})"
                );
            }
        }
    }
    assert_eq!(coarse.geometry().bounds(), geometry.bounds());
    // A constant stays constant at any target resolution, up or down.
    let constant = Grid::filled(geometry, 2.5);
    for dims in [[5, 7, 3], [30, 1, 17]] {
        assert!(
            resample(&constant, dims)
                .unwrap()
                .data()
                .iter()
                .all(|&v| (v - 2.5).abs() < 1e-6)
        );
    }
}

#[test]
fn stats_reduce_in_f64_independently_of_threads() {
    let geometry = GridGeometry::new([33, 17, 9], DVec3::ONE, DVec3::ZERO).unwrap();
    let grid = Grid::from_fn(geometry, |p| (p.x - 10.0) as f32 * 1e-3);
    let sequential: f64 = grid.data().iter().map(|&v| f64::from(v)).sum();
    assert!((grid.sum() - sequential).abs() < 1e-12);
    let s = grid.stats();
    assert_eq!(
        s.min,
        grid.data().iter().copied().fold(f32::INFINITY, f32::min)
    );
    assert!((s.mean - sequential / grid.data().len() as f64).abs() < 1e-15);
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| grid.sum());
    assert_eq!(one_thread.to_bits(), grid.sum().to_bits());
}

#[test]
fn the_noise_cloud_costs_less_bricked_than_dense() {
    let geometry =
        GridGeometry::new([128, 128, 128], DVec3::splat(1.0 / 128.0), DVec3::ZERO).unwrap();
    let cloud = NoiseCloud::new(2026, DVec3::splat(0.5), 0.45)
        .rasterize(geometry)
        .unwrap();
    let bricks = BrickedGrid::from_dense(&cloud, BrickedGrid::DEFAULT_BRICK_SIZE).unwrap();
    eprintln!(
        "noise cloud 128³: bricked {} bytes vs dense {} bytes ({} of {} bricks stored)",
        bricks.memory_bytes(),
        bricks.dense_memory_bytes(),
        bricks.stored_bricks(),
        bricks.brick_dims().iter().product::<usize>()
    );
    assert!(
        bricks.memory_bytes() < bricks.dense_memory_bytes() / 2,
        "the cloud leaves most of its box empty"
    );
    assert!(
        cloud.stats().max > 0.5 && cloud.stats().nonzero_fraction > 0.05,
        "and it is a cloud, not nothing"
    );
}

#[test]
fn invalid_geometry_and_parameters_are_refused() {
    assert!(GridGeometry::new([0, 4, 4], DVec3::ONE, DVec3::ZERO).is_err());
    assert!(GridGeometry::new([4, 4, 4], DVec3::new(1.0, -1.0, 1.0), DVec3::ZERO).is_err());
    assert!(GridGeometry::new([4, 4, 4], DVec3::ONE, DVec3::new(f64::NAN, 0.0, 0.0)).is_err());
    assert!(GridGeometry::new([1 << 20, 1 << 20, 1 << 20], DVec3::ONE, DVec3::ZERO).is_err());
    let geometry = GridGeometry::new([4, 4, 4], DVec3::ONE, DVec3::ZERO).unwrap();
    assert!(Grid::from_vec(geometry, vec![0.0; 63]).is_err());
    let grid = Grid::filled(geometry, 1.0);
    assert!(BrickedGrid::from_dense(&grid, 6).is_err());
    assert!(BrickedGrid::from_dense(&grid, 128).is_err());
    assert!(resample(&grid, [0, 2, 2]).is_err());
}

proptest! {
    #[test]
    fn y_up_to_z_up_moves_every_cell_to_its_rotated_place(
        nx in 1usize..7, ny in 1usize..7, nz in 1usize..7,
        hx in 0.1f64..2.0, hy in 0.1f64..2.0, hz in 0.1f64..2.0,
        ox in -3.0f64..3.0, oy in -3.0f64..3.0, oz in -3.0f64..3.0,
    ) {
        // (x, y, z) → (x, −z, y): the value at each old cell centre is found at the rotated
        // centre, the spacing permutes, and the box's volume is kept.
        let g = GridGeometry::new([nx, ny, nz], DVec3::new(hx, hy, hz), DVec3::new(ox, oy, oz)).unwrap();
        let mut grid = Grid::filled(g, 0.0);
        for (n, v) in grid.data_mut().iter_mut().enumerate() {
            *v = n as f32;
        }
        let turned = grid.y_up_to_z_up();
        let t = turned.geometry();
        prop_assert_eq!(t.dims(), [nx, nz, ny]);
        prop_assert_eq!(t.spacing(), DVec3::new(hx, hz, hy));
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let c = g.cell_centre(i, j, k);
                    let v = t.world_to_voxel(DVec3::new(c.x, -c.z, c.y));
                    let r = v.round();
                    prop_assert!((v - r).abs().max_element() < 1e-9, "{v}");
                    let new = t.index(r.x as usize, r.y as usize, r.z as usize);
                    prop_assert_eq!(turned.data()[new], grid.data()[g.index(i, j, k)]);
                }
            }
        }
    }
}
