//! The renderer's isotropic fluence of a diffusion solve: the scattered fluence plus the
//! sky's uncollided fluence in every channel, also when the lights that enter as
//! uncollided light have fewer channels than the problem (a grey sky with an RGB point
//! light inside the medium: the uncollided sub-problem is grey, the solve is RGB).

use glam::DVec3;
use lucent_core::{
    Angular, Boundary, Field, Light, Medium, Params, Problem, SolveOptions, Spectrum,
};
use lucent_diffusion::DiffusionSolver;
use lucent_grid::{Grid, GridGeometry};
use lucent_optics::Phase;

#[test]
fn every_channel_in_scatters_the_grey_sky() {
    let g = GridGeometry::new([10, 9, 8], DVec3::splat(0.1), DVec3::ZERO).unwrap();
    let medium = Medium {
        sigma_t: vec![Grid::filled(g, 8.0)],
        albedo: vec![Field::Constant(0.9)],
        phase: Phase::Isotropic,
    };
    // The point light is the same in every channel, so every channel's fields must be too.
    let lights = vec![
        Light::Sky {
            radiance: Spectrum::Grey(0.4),
        },
        Light::Point {
            position: DVec3::new(0.52, 0.43, 0.41),
            intensity: Spectrum::Rgb([1.0, 1.0, 1.0]),
        },
    ];
    let problem = Problem::new(g, medium, lights, Boundary::Vacuum, None).unwrap();
    let solver = (DiffusionSolver::MULTIGRID.build)(&Params::default()).unwrap();
    let solution = solver.solve(&problem, &SolveOptions::default()).unwrap();
    let Some(Angular::Lights(lights)) = &solution.angular else {
        panic!("diffusion keeps the lights' transmittance");
    };
    assert_eq!(lights.isotropic_fluence.len(), 3);
    for c in 1..3 {
        assert!(
            lights.isotropic_fluence[c].data() == lights.isotropic_fluence[0].data(),
            "isotropic fluence, channel {c}"
        );
        assert!(
            solution.fluence[c].data() == solution.fluence[0].data(),
            "fluence, channel {c}"
        );
    }
}
