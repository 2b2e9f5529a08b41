//! Diffusion synthetic acceleration (Alcouffe 1977) on `lucent-diffusion`'s multigrid.
//!
//! Source iteration converges like ρ ≈ ω (the albedo) per sweep in thick, scattering
//! media: the slow error modes are nearly isotropic and smooth, exactly what diffusion
//! describes. After the sweep that produced φ^{k+½} from a scattering source of scalar
//! flux φ^k, the error e = φ − φ^{k+½} is estimated by the diffusion equation
//!
//! −∇·(D∇f) + σ_a f = σ_s (φ^{k+½} − φ^k),  D = 1/(3(σ_a + (1 − ḡ)σ_s)),
//!
//! with ḡ the discrete phase matrix's mean cosine, Marshak (Robin, A = 1) conditions on
//! vacuum faces and A = (1 + R)/(1 − R) on faces that reflect a fraction R diffusely; then
//! φ^{k+1} = φ^{k+½} + f, and f/(4π) scattered through the phase matrix is added to the
//! stored in-scattered radiance. The diffusion operator is `lucent-diffusion`'s cell-centred
//! finite volumes, not one derived from the transport closure ("inconsistent" DSA): it is
//! effective while cells are at most a few mean free paths wide and is known to lose
//! effectiveness in much thicker cells (Azmy; Warsa, Wareing & Morel 2004), which the
//! tests measure rather than assume. The hierarchy is built once per solve.

use lucent_core::Stopping;
use lucent_diffusion::{
    Boundaries, CellGeometry, Condition, DiffusionProblem, Multigrid, MultigridSettings, Sources,
};
use lucent_grid::GridGeometry;

use crate::error::DomError;

/// The diffusion problem and its multigrid hierarchy.
pub(crate) struct Dsa {
    problem: DiffusionProblem,
    multigrid: Multigrid,
}

impl Dsa {
    /// `None` when the diffusion problem is singular (no absorption and a fully
    /// reflecting boundary): then nothing leaves, and there is nothing to accelerate with.
    pub(crate) fn new(
        geometry: GridGeometry,
        sigma_t: &[f32],
        sigma_s: &[f32],
        mean_cosine: f64,
        reflectance: f64,
    ) -> Result<Option<Self>, DomError> {
        let floor = 1e-3 / geometry.spacing().max_element();
        let (mut d, mut sa) = (
            Vec::with_capacity(sigma_t.len()),
            Vec::with_capacity(sigma_t.len()),
        );
        for (&t, &s) in sigma_t.iter().zip(sigma_s) {
            let a = f64::from((t - s).max(0.0));
            let transport = (a + (1.0 - mean_cosine) * f64::from(s)).max(floor);
            d.push((1.0 / (3.0 * transport)) as f32);
            sa.push(a as f32);
        }
        let condition = if reflectance >= 1.0 {
            Condition::Neumann { flux: 0.0 }
        } else {
            Condition::Robin {
                a: (1.0 + reflectance) / (1.0 - reflectance),
            }
        };
        let problem = match DiffusionProblem::new(
            CellGeometry::full_box(geometry),
            d,
            sa,
            Boundaries::uniform(condition),
        ) {
            Ok(p) => p,
            Err(lucent_diffusion::DiffusionError::Singular) => return Ok(None),
            Err(e) => return Err(e.into()),
        };
        let multigrid = Multigrid::build(&problem, MultigridSettings::default())?;
        Ok(Some(Self { problem, multigrid }))
    }

    /// The correction f for a residual source σ_s(φ^{k+½} − φ^k) per cell (grid order):
    /// a rough solve to 1e-3 (at most 20 V-cycles), or exactly `cycles` V-cycles from
    /// zero, which is a linear map of the residual (what a Krylov method needs).
    pub(crate) fn correction(
        &self,
        residual: Vec<f32>,
        cycles: Option<usize>,
    ) -> Result<Vec<f64>, DomError> {
        let sources = Sources {
            volumetric: residual,
            ..Sources::default()
        };
        let rhs = self.problem.rhs(&sources)?;
        let mut f = vec![0.0; rhs.len()];
        // A rough solve is enough: the correction only needs to remove the slow modes.
        let stopping = match cycles {
            None => Stopping {
                relative_tolerance: 1e-3,
                max_iterations: 20,
                ..Stopping::default()
            },
            Some(cycles) => Stopping {
                relative_tolerance: 0.0,
                absolute_tolerance: 0.0,
                max_iterations: cycles,
                ..Stopping::default()
            },
        };
        self.multigrid.solve(&rhs, &mut f, &stopping);
        Ok(f)
    }
}
