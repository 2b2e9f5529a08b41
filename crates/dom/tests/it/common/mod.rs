//! Scenes and measures shared by the integration tests of `lucent-dom`.

#![allow(dead_code)]

use glam::DVec3;
use lucent_dom::{DomBoundary, DomProblem};
use lucent_grid::GridGeometry;

/// An isotropic fixed source of 1 per storage direction in the cells whose centres lie
/// within `radius` of `centre` (`m` storage directions; grid order, direction fastest).
pub(crate) fn emission_ball(
    geometry: &GridGeometry,
    m: usize,
    centre: DVec3,
    radius: f64,
) -> Vec<f32> {
    let n = geometry.voxel_count();
    let mut fixed = vec![0.0f32; n * m];
    for c in 0..n {
        let [i, j, k] = geometry.coords(c);
        if (geometry.cell_centre(i, j, k) - centre).length() < radius {
            fixed[c * m..(c + 1) * m].fill(1.0);
        }
    }
    fixed
}

/// A unit cube of `cells`³ at `albedo`, σ_t = `sigma`, glowing in a ball of radius 0.15
/// near its top (`m` storage directions). With `cloud` the extinction swings ±50 % inside
/// a sphere of radius 0.4 and is near vacuum (2 %) outside it, so the medium has thin
/// cells and sharp edges.
pub(crate) fn glowing_cube(
    cells: usize,
    sigma: f64,
    albedo: f64,
    cloud: bool,
    m: usize,
    boundary: DomBoundary,
) -> DomProblem {
    let geometry = GridGeometry::from_bounds([cells; 3], DVec3::ZERO, DVec3::ONE).unwrap();
    let sigma_t: Vec<f32> = (0..geometry.voxel_count())
        .map(|c| {
            let [i, j, k] = geometry.coords(c);
            let p = geometry.cell_centre(i, j, k);
            let shape = if cloud {
                let inside = (p - DVec3::splat(0.5)).length() < 0.4;
                (1.0 + 0.5 * (7.0 * p.x).sin() * (5.0 * p.y).cos())
                    * if inside { 1.0 } else { 0.02 }
            } else {
                1.0
            };
            (sigma * shape) as f32
        })
        .collect();
    let sigma_s = sigma_t
        .iter()
        .map(|t| (f64::from(*t) * albedo) as f32)
        .collect();
    DomProblem {
        fixed: emission_ball(&geometry, m, DVec3::new(0.5, 0.5, 0.8), 0.15),
        geometry,
        sigma_t,
        sigma_s,
        boundary,
    }
}

/// ‖a − b‖ / ‖b‖.
pub(crate) fn relative_l2(a: &[f64], b: &[f64]) -> f64 {
    let num: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
    let den: f64 = b.iter().map(|y| y * y).sum();
    (num / den).sqrt()
}
