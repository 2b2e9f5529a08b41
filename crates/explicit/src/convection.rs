//! Zhang & Ma's illumination: per light, first-order upwind convection–absorption to
//! steady state (Eq. 12, scheme Eq. 16), then one implicit diffusion step for the
//! multiple scattering (Eq. 23); checked cases in docs/reference-cases.md.
//!
//! Per light the energy density ρ obeys ∂ρ/∂t = −c u·∇ρ − σ_a ρ, marched with
//!
//! ρ′ = (1 − σ_a)(ρ − C Σ_a |u_a| (ρ − ρ_upwind(a)))                       (Eq. 16)
//!
//! where C = cΔt/Δx (the paper uses ½) and σ_a ∈ [0, 1] is the absorption *per step*, as
//! the paper has it ([`Model::Paper`]). Boundaries: ρ is held at the light's value on
//! inflow faces (n·u < 0; a ghost layer), outflow faces need nothing (upwind differences
//! never look downstream). A point light inside the grid holds every cell within 2Δx of
//! it at G·ρ_P (Eqs. 14–15), G a Gaussian of width `falloff` (or 1).
//!
//! [`Model::Conservative`] is the physically consistent variant the note argues for:
//! ∂ρ/∂t = −∇·(c u ρ) − c σ_a ρ with σ_a a rate (1/length), fluxes through faces with u
//! at the face centre, so a point light falls off as 1/r² in vacuum, and the absorption
//! per step is σ_a cΔt, which makes the steady state independent of C.
//!
//! Stability (Zhang & Ma T4): the paper states C ≤ 1, the one-dimensional bound. In
//! 3D the scheme is monotone and stable only for C·(|u| + |v| + |w|) ≤ 1
//! ([`crate::stability::upwind`]); `propagate` refuses larger C unless `allow_unstable`.

use glam::DVec3;
use lucent_core::{History, StopReason, Stopping};
use rayon::prelude::*;

use crate::error::ExplicitError;
use crate::lattice::{GrowthMonitor, Lattice};

/// A light of Zhang & Ma's model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Light {
    /// A distant light: direction of propagation (normalised here) and energy density.
    Distant {
        /// Direction the light travels.
        direction: DVec3,
        /// Energy density ρ_D on the inflow faces.
        density: f64,
    },
    /// A point light at `position` (inside or outside the grid).
    Point {
        /// Position (length).
        position: DVec3,
        /// Energy density ρ_P.
        density: f64,
        /// Width of the Gaussian fall-off G (length); `None`: G = 1.
        falloff: Option<f64>,
    },
}

/// The form of the convection–absorption equation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Model {
    /// Eq. 16 as printed: non-conservative, absorption a factor (1 − σ_a) per step.
    #[default]
    Paper,
    /// Conservative fluxes, absorption a rate σ_a (1/length) times cΔt.
    Conservative,
    /// The steady state by short characteristics: each cell's value is the upstream
    /// value where the ray through its centre crosses the previous plane of cell centres
    /// (across the light's dominant axis), interpolated bilinearly from the four cells
    /// there, times the exact attenuation e^{−τ} along that step (τ by the trapezoid rule
    /// on σ_a, which is exact for σ_a linear along the step). For a point light the
    /// interpolated quantity is φ r² (the light's I·T, smooth where φ ∝ 1/r² is not).
    /// Absorption is a rate (1/length). Unconditionally stable and positive (convex
    /// interpolation weights), no Courant number; second order where the field is smooth,
    /// where Eq. 16 and the conservative form are first order (and attenuate a cell by
    /// 1/(1 + σh) instead of e^{−σh}). Marched only by ordered sweeps (one pass for a
    /// distant light).
    Characteristic,
}

/// How the march reaches steady state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sweep {
    /// Layer by layer along the light (planes across its dominant axis for a distant
    /// light, cubic shells around a point light), `iterations` Jacobi updates per layer,
    /// each layer started from its upstream neighbour (`warm_start`) or from zero.
    Layers {
        /// Updates per layer per pass (the paper: 4–5).
        iterations: usize,
        /// Start a layer from the upstream layer instead of zero.
        warm_start: bool,
    },
    /// Global Jacobi: every cell from the previous step (parallel over slabs).
    Jacobi,
    /// Gauss–Seidel in the light's order: each cell set to the fixed point of Eq. 16 from
    /// its upwind neighbours, visited after them (octant loop order for a distant light,
    /// increasing distance for a point light). For a distant light one pass is the exact
    /// steady state; a point light's cells in its own slabs need a second pass or two.
    Ordered,
}

/// What is outside the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Edges {
    /// The light's value on inflow faces (the paper).
    #[default]
    Inflow,
    /// Periodic (for stability studies; distant lights only).
    Periodic,
}

/// Settings of [`propagate`].
#[derive(Debug, Clone, PartialEq)]
pub struct UpwindSettings {
    /// Courant number C = cΔt/Δx; `None`: [`DEFAULT_COURANT`] (the paper's ½) or the
    /// light's stability bound where that is lower ([`courant_bound`]).
    pub courant: Option<f64>,
    /// Paper or conservative form.
    pub model: Model,
    /// Ordered (default: exact and fast), the paper's layers, or global Jacobi.
    pub sweep: Sweep,
    /// Boundary treatment.
    pub edges: Edges,
    /// When to stop: the residual is the largest change of a pass over the largest value,
    /// `max_iterations` the most passes (layer sweeps or Jacobi steps).
    pub stopping: Stopping,
    /// Run even beyond the stability bound (for studies); the growth monitor still stops
    /// a diverging run.
    pub allow_unstable: bool,
    /// Starting field (`None`: zero, the paper's initialisation).
    pub initial: Option<Vec<f64>>,
}

impl Default for UpwindSettings {
    fn default() -> Self {
        Self {
            courant: None,
            model: Model::Paper,
            sweep: Sweep::Ordered,
            edges: Edges::Inflow,
            stopping: Stopping {
                relative_tolerance: 1e-10,
                max_iterations: 10_000,
                ..Stopping::default()
            },
            allow_unstable: false,
            initial: None,
        }
    }
}

/// The result of [`propagate`].
#[derive(Debug, Clone, PartialEq)]
pub struct Propagation {
    /// ρ per cell.
    pub density: Vec<f64>,
    /// Passes run.
    pub iterations: usize,
    /// Largest change of each pass over the largest value.
    pub residuals: Vec<f64>,
    /// Why it stopped.
    pub stop_reason: StopReason,
}

/// An upwind neighbour: a cell of the grid or a ghost outside it holding a value.
#[derive(Debug, Clone, Copy)]
enum Upwind {
    Cell(usize),
    Ghost(f64),
}

pub(crate) struct Setup<'a> {
    pub(crate) lattice: &'a Lattice,
    pub(crate) light: Light,
    pub(crate) model: Model,
    pub(crate) edges: Edges,
    pub(crate) courant: f64,
    pub(crate) absorption: &'a [f64],
    /// Cells held fixed (seed of an interior point light) and their values.
    fixed: Vec<Option<f64>>,
}

impl Setup<'_> {
    fn direction(&self, x: DVec3) -> DVec3 {
        match self.light {
            Light::Distant { direction, .. } => direction,
            Light::Point { position, .. } => (x - position).normalize_or_zero(),
        }
    }

    /// The light's value at a ghost or seed point.
    fn source_value(&self, x: DVec3) -> f64 {
        match self.light {
            Light::Distant { density, .. } => density,
            Light::Point {
                position,
                density,
                falloff,
            } => {
                let d2 = (x - position).length_squared();
                let g = falloff.map_or(1.0, |w| (-0.5 * d2 / (w * w)).exp());
                match self.model {
                    Model::Paper => g * density,
                    Model::Conservative | Model::Characteristic => {
                        g * density / d2.max(0.25 * self.lattice.spacing.powi(2))
                    }
                }
            }
        }
    }

    /// The neighbour of cell `at` one step along `axis` in direction `sign`.
    fn neighbour(&self, at: [usize; 3], axis: usize, step: isize) -> Upwind {
        let n = self.lattice.dims[axis] as isize;
        let mut to = at.map(|v| v as isize);
        to[axis] += step;
        if (0..n).contains(&to[axis]) {
            let s = self.lattice.strides();
            return Upwind::Cell((0..3).map(|a| to[a] as usize * s[a]).sum());
        }
        match self.edges {
            Edges::Periodic => {
                to[axis] = to[axis].rem_euclid(n);
                let s = self.lattice.strides();
                Upwind::Cell((0..3).map(|a| to[a] as usize * s[a]).sum())
            }
            Edges::Inflow => Upwind::Ghost(self.source_value(self.lattice.centre(to))),
        }
    }

    /// The steady value of cell c given its upwind neighbours in `rho`: the fixed point of
    /// [`Setup::update`].
    fn fixed_point(&self, c: usize, rho: &[f64]) -> f64 {
        if let Some(v) = self.fixed[c] {
            return v;
        }
        let at = self.lattice.coords(c);
        let x = self.lattice.centre(at.map(|v| v as isize));
        let value = |u: Upwind| match u {
            Upwind::Cell(i) => rho[i],
            Upwind::Ghost(v) => v,
        };
        match self.model {
            Model::Paper => {
                // ρ = (1 − σ)C Σ|u_a| ρ_up / (σ + (1 − σ)C S), S = Σ|u_a|.
                let u = self.direction(x);
                let (mut inflow, mut s) = (0.0, 0.0);
                for axis in 0..3 {
                    let ua = u[axis];
                    if ua != 0.0 {
                        let up = self.neighbour(at, axis, if ua > 0.0 { -1 } else { 1 });
                        inflow += ua.abs() * value(up);
                        s += ua.abs();
                    }
                }
                let sigma = self.absorption[c];
                let keep = (1.0 - sigma) * self.courant;
                let denominator = sigma + keep * s;
                if denominator > 0.0 {
                    keep * inflow / denominator
                } else {
                    rho[c]
                }
            }
            Model::Characteristic => self.characteristic(c, rho),
            Model::Conservative => {
                // ρ (Σ_out u·n + σh) = Σ_in |u·n| ρ_nb.
                let h = self.lattice.spacing;
                let (mut inflow, mut outflow) = (0.0, self.absorption[c] * h);
                for axis in 0..3 {
                    for side in [-1isize, 1] {
                        let mut face = x;
                        face[axis] += 0.5 * side as f64 * h;
                        let un = self.direction(face)[axis] * side as f64;
                        if un > 0.0 {
                            outflow += un;
                        } else if un < 0.0 {
                            inflow += -un * value(self.neighbour(at, axis, side));
                        }
                    }
                }
                if outflow > 0.0 {
                    inflow / outflow
                } else {
                    rho[c]
                }
            }
        }
    }

    /// The short-characteristic value of cell c from its upstream plane in `rho`
    /// ([`Model::Characteristic`]). The ray through the cell's centre is traced back to
    /// the previous plane of cell centres across the light's dominant axis, or to the box
    /// if it leaves it first; there the upstream value is interpolated bilinearly from the
    /// nodes around it: cell centres, or points of an inflow face, where the light arrives
    /// unattenuated (so the interpolation never reaches across the box's surface, where
    /// the field has a kink).
    fn characteristic(&self, c: usize, rho: &[f64]) -> f64 {
        self.characteristic_with(c, &|i| rho[i], &|i| self.absorption[i])
    }

    /// [`Setup::characteristic`] with `rho` and the setup's absorption holding the cells
    /// from `first` on (a rank's layers and halo): cell i at `i - first`.
    pub(crate) fn characteristic_from(&self, c: usize, rho: &[f64], first: usize) -> f64 {
        self.characteristic_with(c, &|i| rho[i - first], &|i| self.absorption[i - first])
    }

    /// [`Setup::characteristic`] reading ρ and σ_a of cells by index through `rho` and
    /// `absorption`: the one definition the in-memory march and the paged one (which holds
    /// only the planes it needs) share, so both give the same bits.
    pub(crate) fn characteristic_with(
        &self,
        c: usize,
        rho: &impl Fn(usize) -> f64,
        absorption: &impl Fn(usize) -> f64,
    ) -> f64 {
        let s = self.lattice.strides();
        let index = |p: [usize; 3]| p[0] * s[0] + p[1] * s[1] + p[2] * s[2];
        self.characteristic_at(self.lattice.coords(c), &index, rho, absorption)
    }

    /// [`Setup::characteristic_with`] for the cell at `at` (its coordinates), each cell it
    /// reads located by `index` (coordinates to the index `rho` and `absorption` take): the
    /// march over boxes holds a box of cells, indexed from the box's corner.
    pub(crate) fn characteristic_at(
        &self,
        at: [usize; 3],
        index: &impl Fn([usize; 3]) -> usize,
        rho: &impl Fn(usize) -> f64,
        absorption: &impl Fn(usize) -> f64,
    ) -> f64 {
        let l = self.lattice;
        let h = l.spacing;
        let c = index(at);
        let x = l.centre(at.map(|v| v as isize));
        let u = self.direction(x);
        let axis = u.abs().max_position();
        if u[axis] == 0.0 {
            return rho(c);
        }
        let lo = l.origin;
        let hi = l.origin + DVec3::new(l.dims[0] as f64, l.dims[1] as f64, l.dims[2] as f64) * h;
        let point_light = match self.light {
            Light::Point { position, .. } => Some(position),
            Light::Distant { .. } => None,
        };
        // φ r² for a point light (its I·T, smooth where φ is not), φ for a distant one.
        let spread = |y: DVec3| point_light.map_or(1.0, |p| (y - p).length_squared());
        let light_at = |y: DVec3| self.source_value(y) * spread(y);
        let finish = |psi: f64, tau: f64| psi * (-tau).exp() / spread(x);
        // Back along −u: to the box, or to the upstream plane of centres.
        let to_box = (0..3)
            .filter(|&a| u[a] != 0.0)
            .map(|a| {
                if u[a] > 0.0 {
                    (x[a] - lo[a]) / u[a]
                } else {
                    (x[a] - hi[a]) / u[a]
                }
            })
            .fold(f64::INFINITY, f64::min);
        let to_plane = h / u[axis].abs();
        if to_box <= to_plane {
            let y = x - u * to_box;
            return finish(light_at(y), absorption(c) * to_box);
        }
        let y = x - u * to_plane;
        let plane = at[axis] as isize + if u[axis] > 0.0 { -1 } else { 1 };
        let (b, d) = ((axis + 1) % 3, (axis + 2) % 3);
        // The value at a node of the upstream plane: (ψ, σ). A node is a cell index or,
        // where the index leaves the grid, the point of the (inflow) face beside it.
        let node_value = |ib: isize, id: isize| -> (f64, f64) {
            let mut to = [0isize; 3];
            to[axis] = plane;
            to[b] = ib;
            to[d] = id;
            let inside = [b, d]
                .iter()
                .all(|&a| (0..l.dims[a] as isize).contains(&to[a]));
            let clamped = to.map(|v| v.max(0));
            let clamped = [0, 1, 2].map(|a| clamped[a].min(l.dims[a] as isize - 1) as usize);
            let i = index(clamped);
            let mut point = l.centre(to);
            if inside {
                return (rho(i) * spread(point), absorption(i));
            }
            for a in [b, d] {
                point[a] = point[a].clamp(lo[a], hi[a]);
            }
            (light_at(point), absorption(i))
        };
        // Per lateral axis: the position of y in index coordinates (centres at integers,
        // faces at −½ and n − ½), and the nodes around it with their positions.
        let coordinate = |a: usize| (y[a] - lo[a]) / h - 0.5;
        let position = |a: usize, i: isize| -> f64 {
            let n = l.dims[a] as isize;
            if i < 0 {
                -0.5
            } else if i >= n {
                n as f64 - 0.5
            } else {
                i as f64
            }
        };
        // Bilinear: the two nodes that bracket y.
        let linear = |a: usize| -> [(isize, f64); 2] {
            let q = coordinate(a);
            let n = l.dims[a] as isize;
            let i = (q.floor() as isize).clamp(-1, n - 1);
            let (p0, p1) = (position(a, i), position(a, i + 1));
            let t = if p1 > p0 {
                ((q - p0) / (p1 - p0)).clamp(0.0, 1.0)
            } else {
                0.0
            };
            [(i, 1.0 - t), (i + 1, t)]
        };
        // Quadratic: Lagrange weights on the nearest centre and its two neighbours (faces
        // at their half-cell distance where a neighbour leaves the grid).
        let quadratic = |a: usize| -> [(isize, f64); 3] {
            let q = coordinate(a);
            let n = l.dims[a] as isize;
            let centre = (q.round() as isize).clamp(0, n - 1);
            // Faces are nodes only where the light comes in: never reach past an outflow
            // face (shift the stencil inward there; one-sided is still quadratic).
            let start = match (u[a] > 0.0, u[a] < 0.0) {
                (_, true) if centre == 0 && n >= 3 => 0,
                (true, _) if centre == n - 1 && n >= 3 => n - 3,
                _ => centre - 1,
            };
            let nodes = [start, start + 1, start + 2];
            let x = nodes.map(|i| position(a, i));
            let weight = |k: usize| {
                let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                (q - x[i]) * (q - x[j]) / ((x[k] - x[i]) * (x[k] - x[j]))
            };
            [0, 1, 2].map(|k| (nodes[k], weight(k)))
        };
        let (mut lowest, mut highest) = (f64::INFINITY, f64::NEG_INFINITY);
        let (mut bilinear, mut sigma_up) = (0.0, 0.0);
        for (ib, wb) in linear(b) {
            for (id, wd) in linear(d) {
                let (v, s) = node_value(ib, id);
                lowest = lowest.min(v);
                highest = highest.max(v);
                bilinear += wb * wd * v;
                sigma_up += wb * wd * s;
            }
        }
        let mut psi = 0.0;
        for (ib, wb) in quadratic(b) {
            for (id, wd) in quadratic(d) {
                if wb * wd != 0.0 {
                    psi += wb * wd * node_value(ib, id).0;
                }
            }
        }
        // Monotone: the quadratic value, limited to the range of the bracketing nodes
        // (where the field has a kink — a shadow edge, the light entering through a box
        // edge — the quadratic would overshoot).
        let psi = if psi.is_finite() {
            psi.clamp(lowest, highest)
        } else {
            bilinear
        };
        finish(psi, 0.5 * (absorption(c) + sigma_up) * to_plane)
    }

    /// The order of an ordered sweep: every cell after its upwind neighbours.
    fn order(&self) -> Vec<usize> {
        let l = self.lattice;
        let n = l.len();
        match self.light {
            Light::Distant { direction, .. } => {
                let range = |axis: usize| -> Vec<usize> {
                    let r: Vec<usize> = (0..l.dims[axis]).collect();
                    if direction[axis] < 0.0 {
                        r.into_iter().rev().collect()
                    } else {
                        r
                    }
                };
                // The dominant axis outermost: each plane across it is complete before the
                // next starts (short characteristics read their whole upstream plane).
                let s = l.strides();
                let outer = direction.abs().max_position();
                let (b, d) = ((outer + 1) % 3, (outer + 2) % 3);
                let mut out = Vec::with_capacity(n);
                for p in range(outer) {
                    for q in range(d) {
                        for r in range(b) {
                            out.push(p * s[outer] + q * s[d] + r * s[b]);
                        }
                    }
                }
                out
            }
            Light::Point { position, .. } => {
                let mut keyed: Vec<(f64, usize)> = (0..n)
                    .into_par_iter()
                    .map(|c| {
                        let x = l.centre(l.coords(c).map(|v| v as isize));
                        ((x - position).length_squared(), c)
                    })
                    .collect();
                // Stable, as `sort_by`: cells at equal distance stay in index order.
                keyed.par_sort_by(|a, b| a.0.total_cmp(&b.0));
                keyed.into_iter().map(|(_, c)| c).collect()
            }
        }
    }

    /// One update of cell c from `rho`.
    fn update(&self, c: usize, rho: &[f64]) -> f64 {
        if let Some(v) = self.fixed[c] {
            return v;
        }
        let at = self.lattice.coords(c);
        let x = self.lattice.centre(at.map(|v| v as isize));
        let value = |u: Upwind| match u {
            Upwind::Cell(i) => rho[i],
            Upwind::Ghost(v) => v,
        };
        let h = self.lattice.spacing;
        match self.model {
            Model::Paper => {
                let u = self.direction(x);
                let mut change = 0.0;
                for axis in 0..3 {
                    let ua = u[axis];
                    if ua != 0.0 {
                        let up = self.neighbour(at, axis, if ua > 0.0 { -1 } else { 1 });
                        change += ua.abs() * (rho[c] - value(up));
                    }
                }
                (1.0 - self.absorption[c]) * (rho[c] - self.courant * change)
            }
            Model::Characteristic => self.characteristic(c, rho),
            Model::Conservative => {
                // Net outflow Σ_faces (u_f·n) ρ_upwind, u at each face centre.
                let mut outflow = 0.0;
                for axis in 0..3 {
                    for side in [-1isize, 1] {
                        let mut face = x;
                        face[axis] += 0.5 * side as f64 * h;
                        let un = self.direction(face)[axis] * side as f64;
                        let other = self.neighbour(at, axis, side);
                        outflow += if un > 0.0 {
                            un * rho[c]
                        } else {
                            un * value(other)
                        };
                    }
                }
                rho[c] - self.courant * outflow - self.courant * h * self.absorption[c] * rho[c]
            }
        }
    }
}

/// The Courant number an upwind march uses when none is given: the paper's ½, or the
/// stability bound of the light at hand where that is lower ([`courant_bound`]).
pub const DEFAULT_COURANT: f64 = 0.5;

/// The largest stable Courant number of an upwind march of `light` over `absorption`:
/// 1/(|u| + |v| + |w|) for [`Model::Paper`] (the largest over the cells' directions, for a
/// point light), 1/(|u| + |v| + |w| + h·max σ_a) for [`Model::Conservative`]; unbounded
/// for [`Model::Characteristic`], which does not march in time.
pub fn courant_bound(lattice: &Lattice, light: &Light, model: Model, absorption: &[f64]) -> f64 {
    let s_max = match *light {
        Light::Distant { direction, .. } => direction.normalize_or_zero().abs().element_sum(),
        Light::Point { position, .. } => (0..lattice.len())
            .map(|c| {
                let x = lattice.centre(lattice.coords(c).map(|v| v as isize));
                (x - position).normalize_or_zero().abs().element_sum()
            })
            .fold(0.0, f64::max),
    };
    let extra = match model {
        Model::Paper => 0.0,
        Model::Characteristic => return f64::INFINITY,
        Model::Conservative => lattice.spacing * absorption.iter().fold(0.0f64, |a, &b| a.max(b)),
    };
    1.0 / (s_max + extra)
}

/// The checks every march of one light runs first (the absorption, the light, the Courant
/// number against its bound), and the march's setup with no cell held fixed:
/// [`propagate`] and the march on ranks ([`crate::wavefront`]) share them.
pub(crate) fn prepare<'a>(
    lattice: &'a Lattice,
    absorption: &'a [f64],
    light: &Light,
    settings: &UpwindSettings,
) -> Result<Setup<'a>, ExplicitError> {
    lattice.check_field("absorption", absorption)?;
    prepare_part(lattice, absorption, light, settings)
}

/// [`prepare`] with `absorption` for some of the cells (a rank's layers, which it indexes
/// from their first cell): the same checks but its length.
pub(crate) fn prepare_part<'a>(
    lattice: &'a Lattice,
    absorption: &'a [f64],
    light: &Light,
    settings: &UpwindSettings,
) -> Result<Setup<'a>, ExplicitError> {
    if let Some((c, v)) = absorption.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(ExplicitError::Invalid(format!(
            "absorption: {v} in cell {c}"
        )));
    }
    let bad_absorption = match settings.model {
        Model::Paper => absorption.iter().any(|&a| !(0.0..=1.0).contains(&a)),
        Model::Conservative | Model::Characteristic => absorption.iter().any(|&a| a < 0.0),
    };
    if bad_absorption {
        return Err(ExplicitError::Invalid(
            "absorption: per-step values in [0, 1] (paper) or rates ≥ 0 (conservative)".into(),
        ));
    }
    let light = match *light {
        Light::Distant { direction, density } => {
            let d = direction.normalize_or_zero();
            if d == DVec3::ZERO || !d.is_finite() || !density.is_finite() {
                return Err(ExplicitError::Invalid(format!(
                    "distant light {direction:?}, density {density}"
                )));
            }
            Light::Distant {
                direction: d,
                density,
            }
        }
        Light::Point {
            position,
            density,
            falloff,
        } => {
            if !position.is_finite()
                || !density.is_finite()
                || falloff.is_some_and(|w| !(w > 0.0 && w.is_finite()))
            {
                return Err(ExplicitError::Invalid(format!(
                    "point light at {position:?}, density {density}, fall-off {falloff:?}"
                )));
            }
            if settings.edges == Edges::Periodic {
                return Err(ExplicitError::Invalid(
                    "periodic edges are for distant lights".into(),
                ));
            }
            *light
        }
    };
    let limit = courant_bound(lattice, &light, settings.model, absorption);
    let courant = settings.courant.unwrap_or(DEFAULT_COURANT.min(limit));
    if !(courant > 0.0 && courant.is_finite()) {
        return Err(ExplicitError::Invalid(format!("Courant number {courant}")));
    }
    // Short characteristics are not a time march: no Courant number applies.
    if settings.model != Model::Characteristic
        && courant > limit * (1.0 + 1e-12)
        && !settings.allow_unstable
    {
        return Err(ExplicitError::Unstable {
            scheme: "upwind convection",
            parameter: "Courant number",
            limit,
            requested: courant,
        });
    }
    Ok(Setup {
        lattice,
        light,
        model: settings.model,
        edges: settings.edges,
        courant,
        absorption,
        fixed: vec![None; lattice.len()],
    })
}

/// Marches one light to steady state over `absorption` (per step in [0, 1] for
/// [`Model::Paper`], a rate in 1/length for [`Model::Conservative`]).
pub fn propagate(
    lattice: &Lattice,
    absorption: &[f64],
    light: &Light,
    settings: &UpwindSettings,
) -> Result<Propagation, ExplicitError> {
    // The budget counts from here, set-up included, and the set-up's passes over every
    // cell (each a fraction of a second at 144³ on one thread) ask the signal between
    // them: stopped there, nothing has propagated and the field is zero.
    let mut history = History::start();
    let interrupt = settings.stopping.interrupt(history.started());
    let halted_in_set_up = |n: usize| {
        interrupt.halt().map(|halt| Propagation {
            density: vec![0.0; n],
            iterations: 0,
            residuals: vec![1.0],
            stop_reason: halt.stop_reason(1.0),
        })
    };
    let mut setup = prepare(lattice, absorption, light, settings)?;
    let light = setup.light;
    let n = lattice.len();
    if let Some(stopped) = halted_in_set_up(n) {
        return Ok(stopped);
    }
    let h = lattice.spacing;
    let mut reference = match light {
        Light::Distant { density, .. } => density.abs(),
        Light::Point { .. } => 0.0,
    };
    if let Light::Point { position, .. } = light {
        for c in 0..n {
            let x = lattice.centre(lattice.coords(c).map(|v| v as isize));
            if (x - position).length() < 2.0 * h {
                let mut v = setup.source_value(x);
                if settings.model == Model::Characteristic {
                    // The exact attenuation over the short distance, σ of the cell.
                    v *= (-absorption[c] * (x - position).length()).exp();
                }
                setup.fixed[c] = Some(v);
                reference = reference.max(v.abs());
            }
        }
        if let Some(stopped) = halted_in_set_up(n) {
            return Ok(stopped);
        }
        // The largest ghost value bounds the field too.
        for c in 0..n {
            let at = lattice.coords(c);
            for axis in 0..3 {
                for side in [-1isize, 1] {
                    if let Upwind::Ghost(v) = setup.neighbour(at, axis, side) {
                        reference = reference.max(v.abs());
                    }
                }
            }
        }
    }
    let mut rho = match &settings.initial {
        Some(v) => {
            lattice.check_field("initial", v)?;
            reference = reference.max(v.iter().fold(0.0f64, |a, b| a.max(b.abs())));
            v.clone()
        }
        None => vec![0.0; n],
    };
    for (c, f) in setup.fixed.iter().enumerate() {
        if let Some(v) = f {
            rho[c] = *v;
        }
    }
    let monitor = GrowthMonitor {
        reference,
        factor: 1e6,
    };
    let layers = match settings.sweep {
        Sweep::Layers { .. } => Some(layers(&setup)),
        Sweep::Jacobi | Sweep::Ordered => None,
    };
    if let Some(stopped) = halted_in_set_up(n) {
        return Ok(stopped);
    }
    let order = match (settings.sweep, light) {
        (Sweep::Ordered, Light::Point { .. }) => setup.order(),
        (Sweep::Ordered, Light::Distant { .. }) if settings.model != Model::Paper => setup.order(),
        (_, _) if settings.model == Model::Characteristic => setup.order(),
        _ => Vec::new(),
    };
    if let Some(stopped) = halted_in_set_up(n) {
        return Ok(stopped);
    }
    let mut next = rho.clone();
    let mut iteration = 0;
    loop {
        let stop = |reason: StopReason, rho: Vec<f64>, residuals: Vec<f64>, iterations| {
            Ok(Propagation {
                density: rho,
                iterations,
                residuals,
                stop_reason: reason,
            })
        };
        match (&layers, settings.sweep) {
            (
                Some(layers),
                Sweep::Layers {
                    iterations,
                    warm_start,
                },
            ) => {
                next.copy_from_slice(&rho);
                for layer in layers {
                    // The first pass starts each layer from upstream (or zero); later
                    // passes continue from where the last one left it.
                    let start = iteration == 0 && settings.initial.is_none();
                    for &(c, up) in layer.iter().filter(|_| start) {
                        if setup.fixed[c].is_none() {
                            next[c] = if warm_start {
                                up.map_or(next[c], |u| match u {
                                    Upwind::Cell(i) => next[i],
                                    Upwind::Ghost(v) => v,
                                })
                            } else {
                                0.0
                            };
                        }
                    }
                    let mut values = vec![0.0; layer.len()];
                    for _ in 0..iterations {
                        for (v, &(c, _)) in values.iter_mut().zip(layer) {
                            *v = setup.update(c, &next);
                        }
                        for (v, &(c, _)) in values.iter().zip(layer) {
                            next[c] = *v;
                        }
                    }
                }
            }
            (_, Sweep::Ordered) => {
                next.copy_from_slice(&rho);
                if let (Light::Distant { direction, density }, Model::Paper, Edges::Inflow) =
                    (light, settings.model, settings.edges)
                {
                    // One pass in octant order is the exact steady state.
                    ordered_distant(&setup, direction, density, &mut next);
                    iteration += 1;
                    return stop(StopReason::Exact, next, vec![0.0], iteration);
                }
                if let (Light::Distant { .. }, Model::Characteristic, Edges::Inflow) =
                    (light, settings.model, settings.edges)
                {
                    // Every cell comes after its whole upstream stencil: exact in one
                    // pass, plane by plane, a plane's cells in parallel (each reads ρ of
                    // the upstream plane only). The paged march runs the same planes
                    // through two-plane buffers (`PlaneMarch::run`); here the fields are
                    // whole, so each cell reads them directly: the same arithmetic
                    // (`Setup::characteristic_with`), the same bits.
                    let s = lattice.strides();
                    let planes = PlaneMarch::new(&setup);
                    let mut values = vec![0.0f64; planes.plane_len()];
                    for &p in &planes.order {
                        // A plane of 512² cells takes milliseconds; the pass, seconds.
                        // Stopped part way, the planes downstream are still zero.
                        if let Some(halt) = interrupt.halt() {
                            return stop(halt.stop_reason(1.0), next, vec![1.0], iteration);
                        }
                        let (setup, upstream) = (&setup, &next);
                        values.par_iter_mut().enumerate().for_each(|(local, v)| {
                            *v = setup.characteristic_from(planes.cell(p, local, s), upstream, 0);
                        });
                        for (local, v) in values.iter().enumerate() {
                            next[planes.cell(p, local, s)] = *v;
                        }
                    }
                    iteration += 1;
                    return stop(StopReason::Exact, next, vec![0.0], iteration);
                }
                for (k, &c) in order.iter().enumerate() {
                    if k % 65_536 == 0
                        && let Some(halt) = interrupt.halt()
                    {
                        // The last whole pass's field.
                        let last = history.last().min(1.0);
                        return stop(
                            halt.stop_reason(last),
                            rho,
                            history.into_residuals(),
                            iteration,
                        );
                    }
                    next[c] = setup.fixed_point(c, &next);
                }
            }
            _ => {
                let setup = &setup;
                let rho = &rho;
                next.par_iter_mut()
                    .enumerate()
                    .for_each(|(c, v)| *v = setup.update(c, rho));
            }
        }
        iteration += 1;
        if let Some(reason) = monitor.check(&next, iteration) {
            // Return the last field that passed the monitor: always finite.
            return stop(reason, rho, history.into_residuals(), iteration);
        }
        let (mut change, mut largest) = (0.0f64, 0.0f64);
        for (a, b) in next.iter().zip(&rho) {
            change = change.max((a - b).abs());
            largest = largest.max(a.abs());
        }
        let residual = if largest > 0.0 {
            change / largest
        } else {
            change
        };
        std::mem::swap(&mut rho, &mut next);
        if let Some(reason) = history.record_step(&settings.stopping, iteration, residual, change) {
            return stop(reason, rho, history.into_residuals(), iteration);
        }
    }
}

/// The characteristic model's exact pass for a distant light, plane by plane across the
/// light's dominant axis, upstream first: each plane's cells need only the plane before
/// it (their short characteristics end there or at an inflow face), so the march holds
/// two planes of ρ and σ_a, whatever the grid's size. The in-memory march and the paged
/// one both run it; they differ only in where planes come from and go to.
pub(crate) struct PlaneMarch<'a> {
    setup: &'a Setup<'a>,
    /// The light's dominant axis and the two others (b = axis + 1, d = axis + 2, mod 3).
    axis: usize,
    b: usize,
    d: usize,
    /// Planes in marching order.
    order: Vec<usize>,
}

impl<'a> PlaneMarch<'a> {
    fn new(setup: &'a Setup<'a>) -> Self {
        let direction = match setup.light {
            Light::Distant { direction, .. } => direction,
            Light::Point { .. } => DVec3::Z,
        };
        let axis = direction.abs().max_position();
        let n = setup.lattice.dims[axis];
        let order = if direction[axis] < 0.0 {
            (0..n).rev().collect()
        } else {
            (0..n).collect()
        };
        Self {
            setup,
            axis,
            b: (axis + 1) % 3,
            d: (axis + 2) % 3,
            order,
        }
    }

    /// Cells per plane.
    fn plane_len(&self) -> usize {
        let dims = self.setup.lattice.dims;
        dims[self.b] * dims[self.d]
    }

    /// The cell index of position `local` (b fastest, then d) in plane `p`.
    fn cell(&self, p: usize, local: usize, strides: [usize; 3]) -> usize {
        let nb = self.setup.lattice.dims[self.b];
        p * strides[self.axis] + (local % nb) * strides[self.b] + (local / nb) * strides[self.d]
    }

    /// The plane of cell `c` and its position in the plane.
    fn locate(&self, c: usize) -> (usize, usize) {
        let at = self.setup.lattice.coords(c);
        let nb = self.setup.lattice.dims[self.b];
        (at[self.axis], at[self.b] + nb * at[self.d])
    }

    /// Marches every plane: `absorption(p, out)` fills σ_a of plane `p` (positions as in
    /// [`PlaneMarch::cell`]), `emit(p, values)` takes ρ of plane `p`.
    fn run<E: Send>(
        &self,
        mut absorption: impl FnMut(usize, &mut [f64]) -> Result<(), E>,
        mut emit: impl FnMut(usize, &[f64]) -> Result<(), E>,
    ) -> Result<(), E> {
        let len = self.plane_len();
        let strides = self.setup.lattice.strides();
        let (mut sigma, mut sigma_up) = (vec![0.0; len], vec![0.0; len]);
        let (mut rho, mut rho_up) = (vec![0.0; len], vec![0.0; len]);
        let mut upstream: Option<usize> = None;
        for &p in &self.order {
            absorption(p, &mut sigma)?;
            {
                let (sigma, sigma_up, rho_up) = (&sigma, &sigma_up, &rho_up);
                // A cell of this plane or of the one upstream, by index.
                let pick = |c: usize, here: &[f64], there: &[f64]| {
                    let (plane, local) = self.locate(c);
                    if plane == p {
                        here[local]
                    } else if Some(plane) == upstream {
                        there[local]
                    } else {
                        // Never read: a characteristic ends in the upstream plane or at
                        // an inflow face (see `characteristic_with`).
                        f64::NAN
                    }
                };
                rho.par_iter_mut().enumerate().for_each(|(local, v)| {
                    let c = self.cell(p, local, strides);
                    *v = self.setup.characteristic_with(
                        c,
                        &|i| {
                            let (plane, local) = self.locate(i);
                            if Some(plane) == upstream {
                                rho_up[local]
                            } else {
                                f64::NAN
                            }
                        },
                        &|i| pick(i, sigma, sigma_up),
                    );
                });
            }
            emit(p, &rho)?;
            std::mem::swap(&mut rho, &mut rho_up);
            std::mem::swap(&mut sigma, &mut sigma_up);
            upstream = Some(p);
        }
        Ok(())
    }
}

/// The characteristic model's exact march of a distant light of unit density travelling
/// along `direction`, plane by plane (two planes held at a time), for a storage that holds only
/// planes (a paged medium): `absorption(axis, p, out)` fills σ_a (1/length) of plane `p`
/// across `axis`, `emit(axis, p, values)` takes ρ there; a plane's cells are ordered with
/// the next axis (axis + 1 mod 3) fastest, then the one after. Inflow edges. The same
/// arithmetic as [`propagate`] with [`Model::Characteristic`] and [`Sweep::Ordered`].
pub fn march_distant_planes<E: Send>(
    lattice: &Lattice,
    direction: DVec3,
    mut absorption: impl FnMut(usize, usize, &mut [f64]) -> Result<(), E>,
    mut emit: impl FnMut(usize, usize, &[f64]) -> Result<(), E>,
) -> Result<(), E> {
    let setup = Setup {
        lattice,
        light: Light::Distant {
            direction: direction.normalize_or_zero(),
            density: 1.0,
        },
        model: Model::Characteristic,
        edges: Edges::Inflow,
        courant: DEFAULT_COURANT,
        absorption: &[],
        fixed: Vec::new(),
    };
    let march = PlaneMarch::new(&setup);
    let axis = march.axis;
    march.run(
        |p, out| absorption(axis, p, out),
        |p, values| emit(axis, p, values),
    )
}

/// The exact steady state of Eq. 16 for a distant light in one pass: rows in the octant
/// order of the light, each cell the fixed point ρ = (1 − σ)C Σ|u_a|ρ_up / (σ + (1 − σ)CS)
/// of its three upwind neighbours (the light's density beyond inflow faces).
fn ordered_distant(setup: &Setup<'_>, u: DVec3, density: f64, rho: &mut [f64]) {
    let [_, ny, nz] = setup.lattice.dims;
    for kk in 0..nz {
        for jj in 0..ny {
            paper_row(setup, u, density, (rho, 0), [jj, kk]);
        }
    }
}

/// One x-row of [`ordered_distant`]'s pass: the row `jj`-th along y and `kk`-th along z in
/// the light's order (its upwind rows in y and z done), x in the light's order. `rho` and
/// the setup's absorption hold the cells from `first` on (0: all). The march on ranks runs
/// the same rows in another order that keeps every row after its upwind ones.
pub(crate) fn paper_row(
    setup: &Setup<'_>,
    u: DVec3,
    density: f64,
    (rho, first): (&mut [f64], usize),
    [jj, kk]: [usize; 2],
) {
    let l = setup.lattice;
    let [nx, ny, nz] = l.dims;
    let s = l.strides();
    let w = u.abs();
    let total = w.element_sum();
    let (px, py, pz) = (u.x >= 0.0, u.y >= 0.0, u.z >= 0.0);
    let flip = |v: usize, n: usize, positive: bool| if positive { v } else { n - 1 - v };
    let k = flip(kk, nz, pz);
    let j = flip(jj, ny, py);
    // Indices into `rho` and the absorption.
    let row = j * s[1] + k * s[2] - first;
    let y_up = (jj > 0).then(|| if py { row - s[1] } else { row + s[1] });
    let z_up = (kk > 0).then(|| if pz { row - s[2] } else { row + s[2] });
    let mut x_up = density;
    for ii in 0..nx {
        let i = flip(ii, nx, px);
        let c = row + i;
        let from_y = y_up.map_or(density, |r| rho[r + i]);
        let from_z = z_up.map_or(density, |r| rho[r + i]);
        let value = paper_cell(
            setup.courant,
            (w, total),
            [x_up, from_y, from_z],
            setup.absorption[c],
            rho[c],
        );
        rho[c] = value;
        x_up = value;
    }
}

/// One cell of the paper's one-pass march (Eq. 16 at its fixed point): ρ = (1 − σ)C
/// Σ|u_a| ρ_a / (σ + (1 − σ)C Σ|u_a|) from the values `upwind` of its upwind neighbours
/// along x, y and z (the light's density beyond an inflow face), with `w` = |u| and
/// `total` = Σ|u_a|; `old` where the denominator vanishes. [`paper_row`] and the march
/// over boxes (`wavefront::boxes`) share it, so both give the serial bits.
pub(crate) fn paper_cell(
    courant: f64,
    (w, total): (DVec3, f64),
    upwind: [f64; 3],
    sigma: f64,
    old: f64,
) -> f64 {
    let inflow = w.x * upwind[0] + w.y * upwind[1] + w.z * upwind[2];
    let keep = (1.0 - sigma) * courant;
    let denominator = sigma + keep * total;
    if denominator > 0.0 {
        keep * inflow / denominator
    } else {
        old
    }
}

/// The layers of a layer sweep, upstream first, each cell with the neighbour a warm
/// start copies (its upwind neighbour along the dominant axis).
fn layers(setup: &Setup<'_>) -> Vec<Vec<(usize, Option<Upwind>)>> {
    let lattice = setup.lattice;
    let h = lattice.spacing;
    let n = lattice.len();
    let key = |c: usize| -> usize {
        let at = lattice.coords(c);
        match setup.light {
            Light::Distant { direction, .. } => {
                let axis = direction.abs().max_position();
                if direction[axis] > 0.0 {
                    at[axis]
                } else {
                    lattice.dims[axis] - 1 - at[axis]
                }
            }
            Light::Point { position, .. } => {
                let x = lattice.centre(at.map(|v| v as isize));
                ((x - position).abs().max_element() / h).floor() as usize
            }
        }
    };
    let count = (0..n).map(key).max().unwrap_or(0) + 1;
    let mut out: Vec<Vec<(usize, Option<Upwind>)>> = vec![Vec::new(); count];
    for c in 0..n {
        let at = lattice.coords(c);
        let x = lattice.centre(at.map(|v| v as isize));
        let u = setup.direction(x);
        let axis = u.abs().max_position();
        let up =
            (u[axis] != 0.0).then(|| setup.neighbour(at, axis, if u[axis] > 0.0 { -1 } else { 1 }));
        out[key(c)].push((c, up));
    }
    out
}

/// The field of several coloured lights, Eq. 22: L = Σ_k ρ_k L_k, per channel. Each
/// light is (ρ_k, its colour per channel; a single value is grey). Fields of different
/// sizes or empty colours are an error.
pub fn compose(fields: &[(Vec<f64>, Vec<f64>)]) -> Result<Vec<Vec<f64>>, ExplicitError> {
    let channels = fields.iter().map(|(_, c)| c.len()).max().unwrap_or(0);
    let n = fields.first().map_or(0, |(rho, _)| rho.len());
    if fields
        .iter()
        .any(|(rho, colour)| rho.len() != n || colour.is_empty())
    {
        return Err(ExplicitError::Invalid(
            "compose: every light needs a field of one size and a colour".into(),
        ));
    }
    Ok((0..channels)
        .map(|ch| {
            let mut out = vec![0.0; n];
            for (rho, colour) in fields {
                let k = colour[ch.min(colour.len() - 1)];
                for (o, r) in out.iter_mut().zip(rho) {
                    *o += k * r;
                }
            }
            out
        })
        .collect())
}

#[cfg(test)]
mod plane_march_tests {
    use super::*;

    /// The plane-by-plane march gives, bit for bit, what visiting every cell in the
    /// ordered sweep's order gives (the definition it replaces), for suns along each axis
    /// and sign, oblique and grazing, on a grid that is no cube and a medium that varies.
    #[test]
    fn plane_march_equals_the_cell_ordered_sweep() {
        let mut lattice = Lattice::new([11, 7, 9], 0.1).unwrap();
        lattice.origin = DVec3::new(-0.3, 0.2, 0.0);
        let absorption: Vec<f64> = (0..lattice.len())
            .map(|c| {
                let x = lattice.centre(lattice.coords(c).map(|v| v as isize));
                if x.x < 0.2 {
                    0.0
                } else {
                    3.0 + 8.0 * (5.0 * x.y).sin().abs() + x.z
                }
            })
            .collect();
        for direction in [
            DVec3::new(0.3, 0.4, -0.87),
            DVec3::new(-0.9, 0.2, 0.1),
            DVec3::new(0.1, -0.95, 0.2),
            DVec3::new(0.0, 0.0, 1.0),
            DVec3::new(0.7, 0.7, 0.1),
        ] {
            let setup = Setup {
                lattice: &lattice,
                light: Light::Distant {
                    direction: direction.normalize(),
                    density: 1.5,
                },
                model: Model::Characteristic,
                edges: Edges::Inflow,
                courant: 0.5,
                absorption: &absorption,
                fixed: vec![None; lattice.len()],
            };
            let mut ordered = vec![0.0; lattice.len()];
            for c in setup.order() {
                ordered[c] = setup.fixed_point(c, &ordered);
            }
            let march = PlaneMarch::new(&setup);
            let s = lattice.strides();
            let mut planes = vec![0.0; lattice.len()];
            march
                .run(
                    |p, out| {
                        for (local, v) in out.iter_mut().enumerate() {
                            *v = absorption[march.cell(p, local, s)];
                        }
                        Ok::<_, ()>(())
                    },
                    |p, values| {
                        for (local, v) in values.iter().enumerate() {
                            planes[march.cell(p, local, s)] = *v;
                        }
                        Ok(())
                    },
                )
                .unwrap();
            assert!(ordered.iter().any(|&v| v > 0.0));
            let same = ordered
                .iter()
                .zip(&planes)
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same, "{direction:?}");
        }
    }
}
