//! Transfer functions and procedural volumes.

use glam::DVec3;
use lucent_grid::procedural::{NoiseCloud, Shape, gaussian_blob};
use lucent_grid::transfer::{PiecewiseLinear, TransferFunction};
use lucent_grid::{Grid, GridGeometry};
use proptest::prelude::*;

#[test]
fn piecewise_linear_interpolates_and_clamps() {
    let f = PiecewiseLinear::new(vec![[0.0, 1.0], [10.0, 3.0], [20.0, 0.0]]).unwrap();
    for (x, y) in [
        (-5.0, 1.0),
        (0.0, 1.0),
        (5.0, 2.0),
        (10.0, 3.0),
        (15.0, 1.5),
        (20.0, 0.0),
        (99.0, 0.0),
    ] {
        assert!((f.eval(x) - y).abs() < 1e-15, "f({x})");
    }
    assert_eq!(f.eval(f64::NAN), 1.0);
    assert!(PiecewiseLinear::new(vec![]).is_err());
    assert!(PiecewiseLinear::new(vec![[1.0, 0.0], [1.0, 2.0]]).is_err());
    assert!(PiecewiseLinear::new(vec![[0.0, f64::INFINITY]]).is_err());
}

#[test]
fn transfer_functions_deserialise_with_validation() {
    let text = r#"
        density_scale = 20.0
        extinction = [[0.0, 0.0], [80.0, 0.0], [255.0, 1.0]]
        albedo = [[0.0, 0.9]]
        color = { red = [[0.0, 1.0]], green = [[0.0, 0.8]], blue = [[0.0, 0.6]] }
    "#;
    let tf: TransferFunction = toml::from_str(text).unwrap();
    assert!((tf.sigma_t(255.0) - 20.0).abs() < 1e-12);
    assert!((tf.sigma_t(167.5) - 10.0).abs() < 1e-12);
    assert_eq!(tf.sigma_t(40.0), 0.0);
    assert!((tf.albedo(100.0) - 0.9).abs() < 1e-15);

    // Bad input is an error at load time, not a NaN later.
    for bad in [
        "density_scale = -1.0\nextinction = [[0.0, 1.0]]\nalbedo = [[0.0, 0.5]]",
        "density_scale = 1.0\nextinction = [[0.0, 1.0]]\nalbedo = [[0.0, 1.5]]",
        "density_scale = 1.0\nextinction = [[5.0, 1.0], [1.0, 2.0]]\nalbedo = [[0.0, 0.5]]",
        "density_scale = 1.0\nextinction = [[0.0, -1.0]]\nalbedo = [[0.0, 0.5]]",
        "density_scale = 1.0\nextinction = [[0.0, 1.0]]\nalbedo = [[0.0, 0.5]]\ncolour = 3",
    ] {
        assert!(
            toml::from_str::<TransferFunction>(bad).is_err(),
            "accepted: {bad}"
        );
    }
}

#[test]
fn transfer_functions_map_every_cell() {
    let geometry = GridGeometry::new([4, 3, 2], DVec3::ONE, DVec3::ZERO).unwrap();
    let volume = Grid::from_fn(geometry, |p| (p.x * 50.0) as f32);
    let tf = TransferFunction::new(
        2.0,
        PiecewiseLinear::new(vec![[0.0, 0.0], [200.0, 1.0]]).unwrap(),
        PiecewiseLinear::new(vec![[0.0, 0.2], [200.0, 0.8]]).unwrap(),
        None,
    )
    .unwrap();
    let medium = tf.apply(&volume);
    assert!(medium.color.is_none(), "grey media cost one channel");
    for ((&v, &s), &a) in volume
        .data()
        .iter()
        .zip(medium.sigma_t.data())
        .zip(medium.albedo.data())
    {
        let v = f64::from(v);
        assert!((f64::from(s) - 2.0 * v / 200.0).abs() < 1e-6);
        assert!((f64::from(a) - (0.2 + 0.6 * v / 200.0)).abs() < 1e-6);
    }
}

#[test]
fn signed_distances_are_exact_at_known_points() {
    let sphere = Shape::Sphere {
        centre: DVec3::new(1.0, 2.0, 3.0),
        radius: 2.0,
    };
    assert!((sphere.signed_distance(DVec3::new(1.0, 2.0, 3.0)) + 2.0).abs() < 1e-15);
    assert!((sphere.signed_distance(DVec3::new(4.0, 2.0, 3.0)) - 1.0).abs() < 1e-15);
    let cube = Shape::Box {
        min: DVec3::ZERO,
        max: DVec3::ONE,
    };
    assert!((cube.signed_distance(DVec3::splat(0.5)) + 0.5).abs() < 1e-15);
    assert!((cube.signed_distance(DVec3::new(2.0, 2.0, 0.5)) - 2f64.sqrt()).abs() < 1e-15);
    let slab = Shape::Slab {
        normal: DVec3::new(0.0, 0.0, 2.0),
        offset: 1.0,
        thickness: 0.5,
    };
    assert!((slab.signed_distance(DVec3::new(9.0, -3.0, 1.0)) + 0.25).abs() < 1e-15);
    assert!((slab.signed_distance(DVec3::new(0.0, 0.0, 2.0)) - 0.75).abs() < 1e-15);
    let torus = Shape::Torus {
        centre: DVec3::ZERO,
        major: 3.0,
        minor: 1.0,
    };
    assert!((torus.signed_distance(DVec3::new(3.0, 0.0, 0.0)) + 1.0).abs() < 1e-15);
    assert!((torus.signed_distance(DVec3::new(0.0, 0.0, 0.0)) - 2.0).abs() < 1e-15);
    assert!((torus.signed_distance(DVec3::new(0.0, 3.0, 2.0)) - 1.0).abs() < 1e-15);
    for bad in [
        Shape::Sphere {
            centre: DVec3::ZERO,
            radius: 0.0,
        },
        Shape::Box {
            min: DVec3::ONE,
            max: DVec3::ZERO,
        },
        Shape::Slab {
            normal: DVec3::ZERO,
            offset: 0.0,
            thickness: 1.0,
        },
        Shape::Torus {
            centre: DVec3::ZERO,
            major: 1.0,
            minor: 2.0,
        },
    ] {
        assert!(bad.validate().is_err(), "{bad:?}");
    }
}

fn shape_strategy() -> impl Strategy<Value = Shape> {
    let v = || [-2.0f64..2.0, -2.0f64..2.0, -2.0f64..2.0].prop_map(DVec3::from_array);
    prop_oneof![
        (v(), 0.1f64..2.0).prop_map(|(centre, radius)| Shape::Sphere { centre, radius }),
        (v(), [0.1f64..2.0, 0.1f64..2.0, 0.1f64..2.0]).prop_map(|(min, e)| Shape::Box {
            min,
            max: min + DVec3::from_array(e)
        }),
        (v(), -1.0f64..1.0, 0.1f64..1.0).prop_map(|(normal, offset, thickness)| Shape::Slab {
            normal: normal + DVec3::X * 3.0,
            offset,
            thickness
        }),
        (v(), 0.6f64..2.0, 0.1f64..0.5).prop_map(|(centre, major, minor)| Shape::Torus {
            centre,
            major,
            minor
        }),
    ]
}

proptest! {
    #[test]
    fn signed_distance_gradients_have_unit_length(shape in shape_strategy(), p in [-4.0f64..4.0, -4.0f64..4.0, -4.0f64..4.0]) {
        // An exact SDF satisfies |∇d| = 1 wherever it is differentiable. Central differences
        // with step 1e-6 are good to ~1e-6 away from the medial axis and the edges, where
        // d has kinks; points that close to a kink are skipped.
        let p = DVec3::from_array(p);
        let h = 1e-6;
        let d = |q: DVec3| shape.signed_distance(q);
        let grad = DVec3::new(
            d(p + DVec3::X * h) - d(p - DVec3::X * h),
            d(p + DVec3::Y * h) - d(p - DVec3::Y * h),
            d(p + DVec3::Z * h) - d(p - DVec3::Z * h),
        ) / (2.0 * h);
        let second = (0..3).map(|a| {
            let e = DVec3::AXES[a] * 1e-3;
            (d(p + e) - 2.0 * d(p) + d(p - e)).abs() / 1e-6
        }).fold(0.0, f64::max);
        prop_assume!(second < 1e3);
        prop_assert!((grad.length() - 1.0).abs() < 1e-4, "|∇d| = {}", grad.length());
    }
}

#[test]
fn densities_fill_the_inside() {
    let geometry = GridGeometry::new([32, 32, 32], DVec3::splat(1.0 / 32.0), DVec3::ZERO).unwrap();
    let ball = Shape::Sphere {
        centre: DVec3::splat(0.5),
        radius: 0.3,
    };
    let hard = ball.density_grid(geometry, 0.0).unwrap();
    // The cell count inside approximates the ball's volume 4/3 π 0.3³ = 0.1131 (the cells
    // straddling the surface make the staircase error of order h·area = 0.035 at most).
    let volume = hard.sum() * geometry.cell_volume();
    assert!(
        (volume - 4.0 / 3.0 * std::f64::consts::PI * 0.027).abs() < 0.0035,
        "{volume}"
    );
    let soft = ball.density_grid(geometry, 0.1).unwrap();
    assert_eq!(soft.get(16, 16, 16), Some(1.0));
    assert_eq!(soft.get(0, 0, 0), Some(0.0));
    let sdf = ball.sdf_grid(geometry).unwrap();
    let centre = geometry.cell_centre(0, 16, 16);
    assert!(
        (f64::from(sdf.get(0, 16, 16).unwrap()) - ((centre - DVec3::splat(0.5)).length() - 0.3))
            .abs()
            < 1e-7
    );
    let blob = gaussian_blob(geometry, DVec3::splat(0.5), 0.1).unwrap();
    let blob_integral = blob.sum() * geometry.cell_volume();
    // ∫ exp(−r²/2σ²) dV = (2π)^{3/2} σ³, to midpoint-rule accuracy (h/σ = 0.3).
    assert!(
        (blob_integral - (2.0 * std::f64::consts::PI).powf(1.5) * 1e-3).abs() < 1e-5,
        "{blob_integral}"
    );
    assert!(gaussian_blob(geometry, DVec3::ZERO, -1.0).is_err());
}

#[test]
fn noise_clouds_are_seeded_and_deterministic() {
    let geometry = GridGeometry::new([24, 24, 24], DVec3::splat(1.0 / 24.0), DVec3::ZERO).unwrap();
    let a = NoiseCloud::new(1, DVec3::splat(0.5), 0.45)
        .rasterize(geometry)
        .unwrap();
    let b = NoiseCloud::new(1, DVec3::splat(0.5), 0.45)
        .rasterize(geometry)
        .unwrap();
    let c = NoiseCloud::new(2, DVec3::splat(0.5), 0.45)
        .rasterize(geometry)
        .unwrap();
    assert_eq!(a, b);
    assert_ne!(a, c);
    let s = a.stats();
    assert!(s.min >= 0.0 && s.max <= 1.0);
    assert_eq!(a.get(0, 0, 0), Some(0.0), "nothing outside the ball");
    let mut bad = NoiseCloud::new(1, DVec3::ZERO, 1.0);
    bad.octaves = 99;
    assert!(bad.rasterize(geometry).is_err());
}
