//! Regime indicators against closed forms: homogeneous boxes of any size and block (the
//! reduced coefficients, the reduced albedo, the distance to the box cell by cell, the
//! depth along a light's path), a void cavity, lights inside and emission.

use glam::DVec3;
use lucent_core::regime::{Regime, VOID_DEPTH};

// The medium's cells (σ_t h = 0.5 below) are far from void.
const _: () = assert!(VOID_DEPTH < 0.5);
use lucent_core::{Boundary, Field, Light, Medium, Problem, Spectrum};
use lucent_grid::{Grid, GridGeometry};
use lucent_optics::Phase;
use proptest::prelude::*;

fn homogeneous(dims: [usize; 3], h: f64, sigma_t: f32, albedo: f32, g: f64) -> Problem {
    let geometry = GridGeometry::new(dims, DVec3::splat(h), DVec3::ZERO).unwrap();
    let phase = if g == 0.0 {
        Phase::Isotropic
    } else {
        Phase::henyey_greenstein(g).unwrap()
    };
    Problem::new(
        geometry,
        Medium {
            sigma_t: vec![Grid::filled(geometry, sigma_t)],
            albedo: vec![Field::Constant(albedo)],
            phase,
        },
        vec![Light::Directional {
            direction: DVec3::X,
            irradiance: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
        None,
    )
    .unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// In a homogeneous box every region has σ_t′ = σ_t(1 − αg) and α′ = α(1 − g)/(1 − αg)
    /// (the similarity relation), and its boundary distance is the mean over its cells of
    /// σ_t′ h (min over the six faces of the cells to cross, plus half its own): the closed
    /// form, to rounding (σ_t′ is formed in f64 from f32 inputs: 1e-9 relative).
    #[test]
    fn homogeneous_boxes_have_the_closed_form_indicators(
        nx in 1usize..14, ny in 1usize..14, nz in 1usize..14, block in 1usize..9,
        sigma_t in 0.05f32..20.0, albedo in 0.0f32..1.0, g in -0.9f64..0.95,
    ) {
        let h = 0.1;
        let problem = homogeneous([nx, ny, nz], h, sigma_t, albedo, g);
        let regime = Regime::of(&problem, 0, block);
        prop_assert_eq!(regime.dims, [nx, ny, nz].map(|n| n.div_ceil(block)));
        let (t, a) = (f64::from(sigma_t), f64::from(albedo));
        let reduced = t * (1.0 - a * g);
        let alpha = a * (1.0 - g) / (1.0 - a * g);
        let close = |x: f64, y: f64| (x - y).abs() <= 1e-9 * y.abs().max(1e-12);
        for (r, region) in regime.regions.iter().enumerate() {
            prop_assert!(close(region.sigma_t_reduced, reduced), "{region:?}");
            prop_assert!(close(region.reduced_albedo, alpha), "{region:?} vs {alpha}");
            prop_assert_eq!(region.empty_fraction, 0.0);
            let [rx, ry, rz] = [r % regime.dims[0], (r / regime.dims[0]) % regime.dims[1], r / (regime.dims[0] * regime.dims[1])];
            let (mut sum, mut cells) = (0.0, 0.0);
            for k in rz * block..((rz + 1) * block).min(nz) {
                for j in ry * block..((ry + 1) * block).min(ny) {
                    for i in rx * block..((rx + 1) * block).min(nx) {
                        let faces = [i, nx - 1 - i, j, ny - 1 - j, k, nz - 1 - k];
                        let crossed = faces.into_iter().min().unwrap() as f64;
                        sum += (crossed + 0.5) * reduced * h;
                        cells += 1.0;
                    }
                }
            }
            prop_assert!(close(region.boundary_mfp, sum / cells), "{} vs {}", region.boundary_mfp, sum / cells);
            let side = [nx, ny, nz].iter().enumerate().map(|(axis, &n)| {
                let lo = [rx, ry, rz][axis] * block;
                ((lo + block).min(n) - lo) as f64 * h
            }).fold(0.0, f64::max);
            prop_assert!(close(region.thickness_mfp, reduced * side));
        }
    }
}

/// The sun along +x reaches a region's centre x through σ_t x of extinction and σ_t′ x of
/// reduced extinction (the trilinear field is constant inside a homogeneous box, and the
/// line integral is exact); a point light inside a region is 0 away from its own centre's
/// neighbourhood only by the half region between them.
#[test]
fn light_paths_are_the_line_integrals_to_the_region_centres() {
    let problem = homogeneous([16, 8, 8], 0.1, 2.0, 0.9, 0.5);
    let regime = Regime::of(&problem, 0, 4);
    let reduced = 2.0 * (1.0 - 0.9 * 0.5);
    for rx in 0..4 {
        let region = regime.region_of([rx * 4, 0, 0]).unwrap();
        let x = (rx as f64 * 4.0 + 2.0) * 0.1;
        assert!((region.light_depth - 2.0 * x).abs() < 1e-5, "{region:?}");
        assert!((region.source_mfp - reduced * x).abs() < 1e-5, "{region:?}");
    }
    // A point light at the centre of region (1, 0, 0) of the 4-cell blocks: the path to
    // that centre is empty; to the next region's centre, 0.4 long.
    let mut lights = problem.clone();
    lights = Problem::new(
        *lights.geometry(),
        lights.medium().clone(),
        vec![Light::Point {
            position: DVec3::new(0.6, 0.2, 0.2),
            intensity: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
        None,
    )
    .unwrap();
    let regime = Regime::of(&lights, 0, 4);
    assert!(regime.region_of([4, 0, 0]).unwrap().light_depth < 1e-9);
    assert!((regime.region_of([8, 0, 0]).unwrap().light_depth - 2.0 * 0.4).abs() < 1e-5);
    // Outside the grid there is no region.
    assert!(regime.region_of([16, 0, 0]).is_none());
    // The sky reaches the corner region's centre (0.2 from three faces) through 0.4.
    let sky = Problem::new(
        *lights.geometry(),
        lights.medium().clone(),
        vec![Light::Sky {
            radiance: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
        None,
    )
    .unwrap();
    let corner = *Regime::of(&sky, 0, 4).region_of([0, 0, 0]).unwrap();
    assert!((corner.light_depth - 2.0 * 0.2).abs() < 1e-5, "{corner:?}");
}

/// A void cavity (σ_t = 0) is a boundary: the cells next to it are half a cell from it;
/// a region inside it is all empty and has no medium to measure; volume emission makes
/// the regions that emit sources themselves.
#[test]
fn void_and_emission_are_boundaries_and_sources() {
    let geometry = GridGeometry::new([12, 12, 12], DVec3::splat(0.1), DVec3::ZERO).unwrap();
    let mut sigma = Grid::filled(geometry, 5.0);
    for k in 4..8 {
        for j in 4..8 {
            for i in 4..8 {
                assert!(sigma.set(i, j, k, 0.0));
            }
        }
    }
    let mut glow = Grid::filled(geometry, 0.0);
    assert!(glow.set(10, 10, 10, 1.0));
    let problem = Problem::new(
        geometry,
        Medium {
            sigma_t: vec![sigma],
            albedo: vec![Field::Constant(1.0)],
            phase: Phase::Isotropic,
        },
        vec![Light::Emission {
            grid: glow,
            scale: Spectrum::Grey(1.0),
        }],
        Boundary::Vacuum,
        None,
    )
    .unwrap();
    // Regions of 4³: the middle one is the cavity.
    let regime = Regime::of(&problem, 0, 4);
    let cavity = regime.region_of([4, 4, 4]).unwrap();
    assert_eq!(cavity.empty_fraction, 1.0);
    assert_eq!(cavity.sigma_t_reduced, 0.0);
    assert_eq!(cavity.boundary_mfp, 0.0);
    // The region left of the cavity, cells 0..4 in x: each cell's nearest boundary is the
    // box or the cavity, whichever is fewer cells away.
    let left = regime.region_of([0, 4, 4]).unwrap();
    let mut sum = 0.0;
    for k in 4..8usize {
        for j in 4..8usize {
            for i in 0..4usize {
                let crossed = [i, 3 - i, j, 11 - j, k, 11 - k].into_iter().min().unwrap();
                sum += (crossed as f64 + 0.5) * 5.0 * 0.1;
            }
        }
    }
    assert!((left.boundary_mfp - sum / 64.0).abs() < 1e-9, "{left:?}");
    // Emission in the last region: a source there, none elsewhere (no light reaches).
    assert_eq!(regime.region_of([10, 10, 10]).unwrap().light_depth, 0.0);
    assert_eq!(regime.region_of([0, 0, 0]).unwrap().light_depth, 50.0);
    // The summary: one region of the 27 void, α′ = 1 everywhere.
    let summary = regime.summary();
    assert!((summary.empty_fraction - 1.0 / 27.0).abs() < 1e-12);
    assert!((summary.reduced_albedo - 1.0).abs() < 1e-12);
}

/// An embedded body: the cells outside it (SDF ≥ 0) are void, as the solvers treat them
/// (`Medium::masked`), and its surface is the boundary the distances are measured to.
#[test]
fn outside_an_embedded_body_is_void() {
    let problem = homogeneous([16, 16, 16], 0.1, 4.0, 0.99, 0.0);
    let centre = DVec3::splat(0.8);
    let mut sdf = Grid::filled(*problem.geometry(), 0.0);
    for k in 0..16 {
        for j in 0..16 {
            for i in 0..16 {
                let p = problem.geometry().cell_centre(i, j, k);
                assert!(sdf.set(i, j, k, ((p - centre).length() - 0.5) as f32));
            }
        }
    }
    let body = Problem::new(
        *problem.geometry(),
        problem.medium().clone(),
        problem.lights().to_vec(),
        Boundary::Vacuum,
        Some(sdf),
    )
    .unwrap();
    let open = Regime::of(&problem, 0, 4);
    let embedded = Regime::of(&body, 0, 4);
    // The corner region is outside the sphere: all void.
    assert_eq!(embedded.region_of([0, 0, 0]).unwrap().empty_fraction, 1.0);
    assert_eq!(open.region_of([0, 0, 0]).unwrap().empty_fraction, 0.0);
    // The region of cells 8..12 next to the centre is inside but for its far corner
    // (0.35·√3 = 0.61 from the centre: 7 of its 64 cells are outside); the sphere's
    // surface (0.5 from the centre) is nearer than the box (0.8): its cells are closer
    // to a boundary than in the open box, but still deep in the medium.
    let (inside, box_only) = (
        embedded.region_of([8, 8, 8]).unwrap(),
        open.region_of([8, 8, 8]).unwrap(),
    );
    assert_eq!(inside.empty_fraction, 7.0 / 64.0);
    assert!(
        inside.boundary_mfp < box_only.boundary_mfp && inside.boundary_mfp > 0.5,
        "{inside:?} {box_only:?}"
    );
}
