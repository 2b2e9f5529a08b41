//! Cell integrals of a point-like light's uncollided light: where it first collides, and its
//! cell-averaged fluence, conserving the light's power to the accuracy of the face
//! quadrature whatever the grid.
//!
//! For a light at p of intensity I(ω) (a point or spot light; a directional light is the
//! limit of a far one), the uncollided fluence is φ_u(x) = I(ω) T(x)/r² with T = e^{−τ}
//! along the ray from the light. Because dT/ds = −σ_t T along each ray, the power that
//! first collides in a cell is the uncollided power that enters it minus the power that
//! leaves it:
//!
//! C_cell = ∫_cell σ_t φ_u dV = [p ∈ cell] ∫ I dω − ∮_∂cell I T (ω·n)/r² dA
//!
//! (the divergence theorem on the field ω I T/r², whose divergence is −σ_t φ_u away from
//! p). Every face's flux is computed once and shared by the two cells it separates, so the
//! collisions telescope: Σ_cells C = emitted − escaped exactly, whatever quadrature each
//! face uses. Point sampling φ_u at cell centres next to the 1/r² singularity, by
//! contrast, loses up to 30% of the power on coarse grids (the fault this module fixes in
//! the first-collision sources of `dom` and the diffusion solvers). The derivation is in
//! `docs/first-collision.md`.
//!
//! Face quadrature: faces within three cell widths of a point light are integrated in polar
//! coordinates about the foot of the perpendicular from p (θ split at the face's corners,
//! u = d/r in the radial direction, which makes the solid-angle kernel d/r² dr a constant
//! du: exact for T = 1, 8×8 Gauss points per piece); faces within 16 widths by 2×2 Gauss;
//! farther faces and every face of a directional light by the midpoint rule (relative error
//! O(h²/r²), which cancels to O(h³/r³) in the difference of a cell's faces).
//!
//! The cell-average fluence is φ̄ = C/(σ_t,cell V), which is what a solver that holds σ_t
//! constant per cell must use for its balance to hold. Where σ_t,cell h is too small for
//! that quotient to be accurate (a difference of nearly equal fluxes), φ̄ is sampled
//! instead: 2×2×2 Gauss points of I T/r² (far from the light), or for cells next to the
//! light ∮ I T r (ω·n)/r² dA, exact for a transparent cell.
//!
//! Cells away from a point light (all of a directional light's) are sampled at their 2×2×2
//! Gauss points — unless the cell is optically thick (σ_t h ≥ 3/2 and φ_u spans more than
//! e^{1/2} over the points): there the light collides before the points see it (61 % of a
//! vertical sun's power caught at σ_t h = 10, 0.06 % at 50), and the cell takes its six
//! faces' fluxes instead, by 2×2 Gauss points. The derivation and the measurements are in
//! `docs/first-collision.md`.

use glam::DVec3;
use lucent_grid::{EmptyBricks, Grid, GridGeometry};
use rayon::prelude::*;

use crate::direct::DirectSolver;
use crate::error::SolveError;
use crate::interrupt::{Halt, Interrupt};
use crate::problem::{Light, Problem};
use crate::solution::{Angular, Solution};
use crate::solver::{SolveOptions, Solver};

/// The cell integrals of one light's uncollided light, per unit of its spectrum.
#[derive(Debug, Clone, PartialEq)]
pub struct UncollidedCells {
    /// Power that first collides in each cell, ∫_cell σ_t φ_u dV (W).
    pub collided: Vec<f64>,
    /// ∫_cell σ_t φ_u ω dV: the collided power times its mean direction of travel (W); its
    /// length is at most `collided` (0 for the cell holding a point light, whose light
    /// leaves in every direction).
    pub directed: Vec<DVec3>,
    /// The cell-averaged uncollided fluence (W/length²).
    pub fluence: Vec<f64>,
    /// Power that enters the box (or is emitted inside it) (W).
    pub emitted: f64,
    /// Power that leaves the box without colliding (W).
    pub escaped: f64,
}

impl UncollidedCells {
    /// |emitted − Σ collided − escaped| / emitted: zero up to round-off (the face fluxes
    /// telescope).
    pub fn relative_imbalance(&self) -> f64 {
        let collided: f64 = self.collided.iter().sum();
        if self.emitted > 0.0 {
            (self.emitted - collided - self.escaped).abs() / self.emitted
        } else {
            0.0
        }
    }
}

/// The mean of e^{−s} over a chord of optical length x centred on s = 0 (relative to the
/// centre's value): 2 sinh(x/2)/x.
fn chord_average(x: f64) -> f64 {
    if x < 1e-4 {
        1.0 + x * x / 24.0
    } else {
        2.0 * (0.5 * x).sinh() / x
    }
}

/// Where the light comes from.
#[derive(Clone, Copy)]
enum Source {
    Directional(DVec3),
    Point(DVec3),
}

/// Gauss–Legendre nodes and weights on (−1, 1) for the few orders used here.
fn gauss(n: usize) -> (&'static [f64], &'static [f64]) {
    const X2: [f64; 2] = [-0.577_350_269_189_625_8, 0.577_350_269_189_625_8];
    const W2: [f64; 2] = [1.0, 1.0];
    const X8: [f64; 8] = [
        -0.960_289_856_497_536_3,
        -0.796_666_477_413_626_7,
        -0.525_532_409_916_329,
        -0.183_434_642_495_649_8,
        0.183_434_642_495_649_8,
        0.525_532_409_916_329,
        0.796_666_477_413_626_7,
        0.960_289_856_497_536_3,
    ];
    const W8: [f64; 8] = [
        0.101_228_536_290_376_26,
        0.222_381_034_453_374_47,
        0.313_706_645_877_887_3,
        0.362_683_783_378_362,
        0.362_683_783_378_362,
        0.313_706_645_877_887_3,
        0.222_381_034_453_374_47,
        0.101_228_536_290_376_26,
    ];
    match n {
        2 => (&X2, &W2),
        _ => (&X8, &W8),
    }
}

/// One axis-aligned face: the plane x_axis = `level`, spanning [lo, hi] in the other two
/// axes (`lo`/`hi` are full 3D corners; their `axis` components equal `level`).
#[derive(Clone, Copy)]
struct Face {
    axis: usize,
    lo: DVec3,
    hi: DVec3,
}

/// What a face contributes: flux of uncollided power through it along +axis, the same
/// weighted by the direction of travel, and ∮-type integral of I T r (ω·n)/r² (for
/// transparent cells next to a point light).
#[derive(Clone, Copy, Default)]
struct FaceFlux {
    power: f64,
    directed: DVec3,
    radial: f64,
}

impl std::ops::AddAssign for FaceFlux {
    fn add_assign(&mut self, o: Self) {
        self.power += o.power;
        self.directed += o.directed;
        self.radial += o.radial;
    }
}

/// The uncollided light of one point-like light through some σ_t: the face and cell rules
/// above, with the optical depth τ(a, b) handed in by the caller (`tau`), so that a dense
/// grid and a paged one run the same arithmetic.
pub(crate) struct Integrator<'a> {
    light: &'a Light,
    source: Source,
    far: f64,
    /// Cell size scale for the near/far face rules.
    h: f64,
    geometry: GridGeometry,
    /// The light's whole power and first moment (per unit of its spectrum).
    power: f64,
    moment: DVec3,
    /// The cell (possibly outside the grid) holding a point light.
    light_cell: Option<[i64; 3]>,
}

/// What [`Integrator::cell`] finds in one cell.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CellValues {
    pub(crate) fluence: f64,
    pub(crate) collided: f64,
    pub(crate) directed: DVec3,
}

impl<'a> Integrator<'a> {
    /// The integrator of `light` on `g`; `None` for sky and emission, which are not
    /// point-like.
    pub(crate) fn new(g: &GridGeometry, light: &'a Light) -> Option<Self> {
        let (lo, hi) = g.bounds();
        let h = g.spacing();
        let far = 4.0 * (hi - lo).length() + 1.0;
        let source = match *light {
            Light::Directional { direction, .. } => Source::Directional(direction),
            Light::Point { position, .. } | Light::Spot { position, .. } => {
                // A light exactly on a face plane of the grid would sit on faces whose
                // polar rule is 0/0: move it a billionth of a cell into the cell above.
                let mut p = position;
                let v = (p - g.origin()) / h;
                for axis in 0..3 {
                    if (v[axis] - v[axis].round()).abs() < 1e-9 {
                        p[axis] = g.origin()[axis] + (v[axis].round() + 1e-9) * h[axis];
                    }
                }
                Source::Point(p)
            }
            Light::Sky { .. } | Light::Emission { .. } => return None,
        };
        let (power, moment) = light_power(light);
        let light_cell = match source {
            Source::Point(p) => {
                let v = ((p - g.origin()) / h).floor();
                Some([v.x as i64, v.y as i64, v.z as i64])
            }
            Source::Directional(_) => None,
        };
        Some(Self {
            light,
            source,
            far,
            h: h.max_element(),
            geometry: *g,
            power,
            moment,
            light_cell,
        })
    }

    /// I(ω) T(y) and the direction of travel at a point y, per unit of the light's spectrum.
    fn radiance_at<E>(
        &self,
        y: DVec3,
        tau: &mut impl FnMut(DVec3, DVec3) -> Result<f64, E>,
    ) -> Result<(f64, DVec3, f64), E> {
        match self.source {
            Source::Directional(d) => {
                let t = (-tau(y - d * self.far, y)?).exp();
                Ok((t, d, 0.0))
            }
            Source::Point(p) => {
                let v = y - p;
                let r = v.length();
                if r == 0.0 {
                    return Ok((0.0, DVec3::ZERO, 0.0));
                }
                // I(ω): the light's irradiance at unit distance along ω (the light may sit a
                // billionth of a cell from `p`, which must not enter its 1/r²).
                let omega = v / r;
                let intensity = match *self.light {
                    Light::Point { position, .. } | Light::Spot { position, .. } => self
                        .light
                        .arrival(position + omega, self.far, 0.0)
                        .map_or(0.0, |(_, e, _)| e),
                    _ => 0.0,
                };
                if intensity == 0.0 {
                    return Ok((0.0, v / r, r));
                }
                let t = (-tau(p, y)?).exp();
                Ok((intensity * t, v / r, r))
            }
        }
    }

    /// The kernel (ω·n)/r² (point) or ω·n (directional) at y, for the face normal +axis.
    fn kernel(&self, y: DVec3, axis: usize) -> f64 {
        match self.source {
            Source::Directional(d) => d[axis],
            Source::Point(p) => {
                let v = y - p;
                let r2 = v.length_squared();
                if r2 == 0.0 {
                    0.0
                } else {
                    v[axis] / (r2 * r2.sqrt())
                }
            }
        }
    }

    /// Tensor Gauss rule with `n`×`n` points (n = 1: midpoint).
    fn face_tensor<E>(
        &self,
        face: Face,
        n: usize,
        tau: &mut impl FnMut(DVec3, DVec3) -> Result<f64, E>,
    ) -> Result<FaceFlux, E> {
        let (b, c) = ((face.axis + 1) % 3, (face.axis + 2) % 3);
        let area = (face.hi[b] - face.lo[b]) * (face.hi[c] - face.lo[c]);
        let mut out = FaceFlux::default();
        let mut visit = |y: DVec3, w: f64| -> Result<(), E> {
            let (value, omega, r) = self.radiance_at(y, tau)?;
            let k = self.kernel(y, face.axis) * w;
            out.power += k * value;
            out.directed += omega * (k * value);
            out.radial += k * value * r;
            Ok(())
        };
        if n == 1 {
            visit(0.5 * (face.lo + face.hi), area)?;
            return Ok(out);
        }
        let (x, w) = gauss(n);
        for (xb, wb) in x.iter().zip(w) {
            for (xc, wc) in x.iter().zip(w) {
                let mut y = 0.5 * (face.lo + face.hi);
                y[b] += 0.5 * xb * (face.hi[b] - face.lo[b]);
                y[c] += 0.5 * xc * (face.hi[c] - face.lo[c]);
                visit(y, 0.25 * area * wb * wc)?;
            }
        }
        Ok(out)
    }

    /// Polar rule about the foot of the perpendicular from the point light `p`: θ pieces
    /// between the corners' directions, u = |d|/r radially (the kernel d/r² dr = ∓du).
    fn face_polar<E>(
        &self,
        face: Face,
        p: DVec3,
        tau: &mut impl FnMut(DVec3, DVec3) -> Result<f64, E>,
    ) -> Result<FaceFlux, E> {
        let (a, b, c) = (face.axis, (face.axis + 1) % 3, (face.axis + 2) % 3);
        let d = face.lo[a] - p[a];
        if d == 0.0 {
            return Ok(FaceFlux::default());
        }
        let (fb, fc) = (p[b], p[c]);
        let (b0, b1, c0, c1) = (face.lo[b], face.hi[b], face.lo[c], face.hi[c]);
        let inside = fb > b0 && fb < b1 && fc > c0 && fc < c1;
        // Corner angles about the foot, unwrapped around the direction to the face centre.
        let centre = (0.5 * (b0 + b1) - fb, 0.5 * (c0 + c1) - fc);
        let reference = if inside {
            0.0
        } else {
            centre.1.atan2(centre.0)
        };
        let wrap = |t: f64| {
            let mut t = t - reference;
            while t > std::f64::consts::PI {
                t -= 2.0 * std::f64::consts::PI;
            }
            while t <= -std::f64::consts::PI {
                t += 2.0 * std::f64::consts::PI;
            }
            t
        };
        let mut angles: Vec<f64> = [(b0, c0), (b1, c0), (b1, c1), (b0, c1)]
            .iter()
            .map(|&(x, y)| wrap((y - fc).atan2(x - fb)))
            .collect();
        angles.sort_by(f64::total_cmp);
        if inside {
            angles.push(angles[0] + 2.0 * std::f64::consts::PI);
        }
        // The 2D ray from the foot along θ meets the rectangle in [ρ_in, ρ_out].
        let chord = |theta: f64| -> Option<(f64, f64)> {
            let (s, co) = theta.sin_cos();
            let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
            for (origin, dir, lo, hi) in [(fb, co, b0, b1), (fc, s, c0, c1)] {
                if dir.abs() < 1e-300 {
                    if origin < lo || origin > hi {
                        return None;
                    }
                } else {
                    let (ta, tb) = ((lo - origin) / dir, (hi - origin) / dir);
                    t0 = t0.max(ta.min(tb));
                    t1 = t1.min(ta.max(tb));
                }
            }
            (t1 > t0).then_some((t0, t1))
        };
        let (x, w) = gauss(8);
        let sign = d.signum();
        let ad = d.abs();
        let mut out = FaceFlux::default();
        for piece in angles.windows(2) {
            let (ta, tb) = (piece[0], piece[1]);
            if tb - ta < 1e-15 {
                continue;
            }
            for (xt, wt) in x.iter().zip(w) {
                let theta = reference + 0.5 * (ta + tb) + 0.5 * (tb - ta) * xt;
                let Some((rho_in, rho_out)) = chord(theta) else {
                    continue;
                };
                let wtheta = 0.5 * (tb - ta) * wt;
                let (u_in, u_out) = (
                    ad / (rho_in * rho_in + d * d).sqrt(),
                    ad / (rho_out * rho_out + d * d).sqrt(),
                );
                let (s, co) = theta.sin_cos();
                for (xu, wu) in x.iter().zip(w) {
                    let u = 0.5 * (u_in + u_out) + 0.5 * (u_in - u_out) * xu;
                    let weight = sign * wtheta * 0.5 * (u_in - u_out) * wu;
                    let r = ad / u;
                    let rho = (r * r - d * d).max(0.0).sqrt();
                    let mut y = p;
                    y[a] = face.lo[a];
                    y[b] = fb + rho * co;
                    y[c] = fc + rho * s;
                    let (value, omega, r) = self.radiance_at(y, tau)?;
                    out.power += weight * value;
                    out.directed += omega * (weight * value);
                    out.radial += weight * value * r;
                }
            }
        }
        Ok(out)
    }

    /// The flux through a face: the polar rule for the faces of cells next to a point light
    /// (`near`) and within three cell widths of it, 2×2 Gauss elsewhere.
    fn face<E>(
        &self,
        face: Face,
        near: bool,
        tau: &mut impl FnMut(DVec3, DVec3) -> Result<f64, E>,
    ) -> Result<FaceFlux, E> {
        match self.source {
            Source::Point(p) if near || (p.clamp(face.lo, face.hi) - p).length() < 3.0 * self.h => {
                self.face_polar(face, p, tau)
            }
            _ => self.face_tensor(face, 2, tau),
        }
    }

    /// (1/V) ∫_cell φ_u dV and (1/V) ∫_cell φ_u ω dV by 2×2×2 Gauss points (cells away
    /// from a point light), and the range of φ_u over them.
    fn sampled<E>(
        &self,
        [i, j, k]: [usize; 3],
        tau: &mut impl FnMut(DVec3, DVec3) -> Result<f64, E>,
    ) -> Result<Sampled, E> {
        let g = &self.geometry;
        let (x, w) = gauss(2);
        let centre = g.cell_centre(i, j, k);
        let h = g.spacing();
        let mut phi = 0.0;
        let mut directed = DVec3::ZERO;
        let (mut lowest, mut highest) = (f64::INFINITY, 0.0f64);
        for (xa, wa) in x.iter().zip(w) {
            for (xb, wb) in x.iter().zip(w) {
                for (xc, wc) in x.iter().zip(w) {
                    let y = centre + 0.5 * h * DVec3::new(*xa, *xb, *xc);
                    let (value, omega, r) = self.radiance_at(y, tau)?;
                    let spread = match self.source {
                        Source::Directional(_) => 1.0,
                        Source::Point(_) => 1.0 / (r * r).max(1e-300),
                    };
                    lowest = lowest.min(value * spread);
                    highest = highest.max(value * spread);
                    let v = 0.125 * wa * wb * wc * value * spread;
                    phi += v;
                    directed += omega * v;
                }
            }
        }
        Ok(Sampled {
            fluence: phi,
            directed,
            range: if highest > 0.0 {
                (highest / lowest).ln()
            } else {
                0.0
            },
        })
    }

    /// The face of cell `c` (possibly outside the grid) on its lower side along `axis`.
    fn lower_face(&self, c: [i64; 3], axis: usize) -> Face {
        let g = &self.geometry;
        let h = g.spacing();
        let corner =
            |c: [i64; 3]| g.origin() + DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64) * h;
        let mut far_corner = c;
        far_corner[(axis + 1) % 3] += 1;
        far_corner[(axis + 2) % 3] += 1;
        Face {
            axis,
            lo: corner(c),
            hi: corner(far_corner),
        }
    }

    /// Whether cell `c` is within [`NEAR_CELLS`] of a point light's cell along every axis.
    fn near(&self, c: [i64; 3]) -> bool {
        self.light_cell
            .is_some_and(|l| (0..3).all(|a| c[a].abs_diff(l[a]) <= NEAR_CELLS.unsigned_abs()))
    }

    /// The cell integrals of cell `at`, whose σ_t (at its centre, as the grid stores it)
    /// is `sigma`.
    pub(crate) fn cell<E>(
        &self,
        at: [usize; 3],
        sigma: f64,
        tau: &mut impl FnMut(DVec3, DVec3) -> Result<f64, E>,
    ) -> Result<CellValues, E> {
        let g = &self.geometry;
        let volume = g.cell_volume();
        let h = g.spacing();
        let c = at.map(|v| v as i64);
        let near = self.near(c);
        if !near {
            let sampled = self.sampled(at, tau)?;
            // The Gauss points hold where φ_u varies gently across the cell. Where the cell
            // is optically thick (σ_t h ≥ 3/2) and φ_u falls by more than e^{1/2} between
            // them, the light collides before the points see it (at σ_t h = 10 under a
            // vertical sun they caught 61 % of it, at 50 0.06 %), and the cell takes the
            // face fluxes below. Thinner cells keep the points: their own attenuation errs
            // by about (σ_t h)⁴/4320 there, and C/(σ_t V) from faces would carry the rays'
            // trilinear σ_t into the cell's constant one (`docs/first-collision.md`).
            if sampled.range <= THICK_RANGE || sigma * h.min_element() < THICK_CELL {
                return Ok(CellValues {
                    fluence: sampled.fluence,
                    collided: sigma * sampled.fluence * volume,
                    directed: sampled.directed * (sigma * volume),
                });
            }
        }
        // Net inflow through the six faces, plus the light's power in its own cell.
        let mut net = FaceFlux::default();
        for axis in 0..3 {
            let mut above = c;
            above[axis] += 1;
            let inflow = self.face(self.lower_face(c, axis), near, tau)?;
            let outflow = self.face(self.lower_face(above, axis), near, tau)?;
            net += inflow;
            net += FaceFlux {
                power: -outflow.power,
                directed: -outflow.directed,
                radial: -outflow.radial,
            };
        }
        let (mut cell_power, mut m) = (net.power, net.directed);
        if self.light_cell == Some(c) {
            cell_power += self.power;
            m += self.moment;
        }
        // C/(σV) is a difference of nearly equal fluxes divided by σ h: the polar rule's
        // relative error (below 1e-9) allows it down to σ h = 1e-6. Below that the cell is
        // transparent, and ∮ I T r (ω·n)/r² dA, which is ∫ I T/r² dV − ∫ σ_t I T/r dV, is
        // its integral.
        let fluence = if sigma * h.min_element() >= 1e-6 {
            cell_power / (sigma * volume)
        } else {
            net.radial / volume
        };
        Ok(CellValues {
            fluence,
            collided: cell_power,
            directed: m,
        })
    }
}

/// What [`Integrator::sampled`] finds: the Gauss averages of φ_u and φ_u ω over a cell, and
/// ln(largest/smallest) of φ_u over its points.
struct Sampled {
    fluence: f64,
    directed: DVec3,
    range: f64,
}

/// The ln(max/min) of φ_u over a cell's Gauss points above which a thick cell takes face
/// fluxes (below it the light barely varies across the cell: its shadow is not the cell's).
const THICK_RANGE: f64 = 0.5;

/// σ_t h below which a cell keeps its Gauss points whatever their range: their error on
/// the cell's own attenuation is about (σ_t h)⁴/4320 (1.2e-3 here under a vertical sun),
/// while φ̄ = C/(σ_t V) from face fluxes takes the rays' trilinear extinction into the
/// cell's constant one, a bias where σ_t varies (measured on the suite's cloud, σ_t h ≤
/// 1.2: `dom` 2.2 % against Monte Carlo with the points, 3.0 % with faces from σ_t h = 1,
/// 6.3 % from 1/2), and amplifies the face rule's error by 1/(σ_t h).
const THICK_CELL: f64 = 1.5;

/// Cells within this many of a point light's cell (along each axis) are integrated by face
/// fluxes; farther cells by 2×2×2 Gauss points, whose relative error on 1/r² is below
/// about 1e-3 from three cells on, unless they are optically thick along the light
/// ([`THICK_RANGE`], [`THICK_CELL`]).
const NEAR_CELLS: i64 = 3;

/// The whole power a light sends out (per unit of its spectrum), and its first moment.
fn light_power(light: &Light) -> (f64, DVec3) {
    match *light {
        Light::Point { .. } => (4.0 * std::f64::consts::PI, DVec3::ZERO),
        Light::Spot {
            direction,
            inner_angle,
            outer_angle,
            ..
        } => {
            // ∫ falloff dω = 2π[(1 − cos θ_i) + ½(cos θ_i − cos θ_o)] (the smoothstep's mean
            // is ½); its first moment by an 8-point rule on the ramp.
            let (ci, co) = (inner_angle.cos(), outer_angle.cos());
            let two_pi = 2.0 * std::f64::consts::PI;
            let power = two_pi * ((1.0 - ci) + 0.5 * (ci - co));
            let (x, w) = gauss(8);
            let mut moment = two_pi * 0.5 * (1.0 - ci * ci);
            for (x, w) in x.iter().zip(w) {
                let c = 0.5 * (ci + co) + 0.5 * (ci - co) * x;
                let t = (c - co) / (ci - co);
                moment += two_pi * 0.5 * (ci - co) * w * t * t * (3.0 - 2.0 * t) * c;
            }
            (power, direction * moment)
        }
        _ => (0.0, DVec3::ZERO),
    }
}

/// The uncollided cell integrals of `light` (directional, point or spot) through the
/// trilinear extinction `sigma_t`, marching each ray until its optical depth reaches
/// `cutoff`. `None` for sky and emission, which are not point-like.
pub fn uncollided_cells(sigma_t: &Grid, light: &Light, cutoff: f64) -> Option<UncollidedCells> {
    // Never interrupted: never an `Err`.
    uncollided_cells_within(sigma_t, light, cutoff, &Interrupt::never())
        .ok()
        .flatten()
}

/// [`uncollided_cells`], stopped by `interrupt` (asked every row of cells and every row of
/// a box face's fluxes): `Err` with why, when it stopped before the integrals were whole.
pub fn uncollided_cells_within(
    sigma_t: &Grid,
    light: &Light,
    cutoff: f64,
    interrupt: &Interrupt,
) -> Result<Option<UncollidedCells>, Halt> {
    let g = *sigma_t.geometry();
    let Some(integrator) = Integrator::new(&g, light) else {
        return Ok(None);
    };
    let empty = EmptyBricks::of(sigma_t, 8).ok();
    // Empty space is crossed unread; the integrals keep their bits.
    let tau = |a: DVec3, b: DVec3| {
        Ok::<f64, std::convert::Infallible>(match &empty {
            Some(empty) => sigma_t.line_integral_skipping(empty, a, b, cutoff),
            None => sigma_t.line_integral(a, b, cutoff),
        })
    };
    let [nx, ny, nz] = g.dims();
    let dims = [nx as i64, ny as i64, nz as i64];
    let slab = g.slab_len();
    let n = g.voxel_count();
    let mut collided = vec![0.0; n];
    let mut directed = vec![DVec3::ZERO; n];
    let mut fluence = vec![0.0; n];
    collided
        .par_chunks_mut(slab)
        .zip(directed.par_chunks_mut(slab))
        .zip(fluence.par_chunks_mut(slab))
        .enumerate()
        .for_each(|(k, ((collided, directed), fluence))| {
            let mut tau = tau;
            for ij in 0..slab {
                if ij % nx == 0 && interrupt.halted() {
                    return;
                }
                let sigma = f64::from(sigma_t.data()[ij + slab * k]);
                let Ok(cell) = integrator.cell([ij % nx, ij / nx, k], sigma, &mut tau);
                fluence[ij] = cell.fluence;
                collided[ij] = cell.collided;
                directed[ij] = cell.directed;
            }
        });
    // What enters and leaves the box: fluxes through its faces, and the power of a light
    // inside it.
    let mut emitted = match integrator.light_cell {
        Some(l) if (0..3).all(|a| l[a] >= 0 && l[a] < dims[a]) => integrator.power,
        _ => 0.0,
    };
    let mut escaped = 0.0;
    for axis in 0..3 {
        let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
        for (level, inward) in [(0i64, 1.0), (dims[axis], -1.0)] {
            if let Some(halt) = interrupt.halt() {
                return Err(halt);
            }
            let faces: Vec<f64> = (0..dims[b] * dims[c])
                .into_par_iter()
                .map(|index| {
                    if index % dims[b] == 0 && interrupt.halted() {
                        return 0.0;
                    }
                    let mut cell = [0i64; 3];
                    cell[axis] = level;
                    cell[b] = index % dims[b];
                    cell[c] = index / dims[b];
                    let mut tau = tau;
                    let Ok(flux) =
                        integrator.face(integrator.lower_face(cell, axis), false, &mut tau);
                    flux.power * inward
                })
                .collect();
            for f in faces {
                emitted += f.max(0.0);
                escaped += (-f).max(0.0);
            }
        }
    }
    if let Some(halt) = interrupt.halt() {
        return Err(halt);
    }
    Ok(Some(UncollidedCells {
        collided,
        directed,
        fluence,
        emitted,
        escaped,
    }))
}

/// The uncollided light of a problem's lights as the solvers that add scattered light
/// take it: `direct`'s solution (per-light transmittance at cell centres for the
/// renderer's exact single scattering, and the sky's uncollided fluence, which in-scatters
/// isotropically) and each point-like light's [`UncollidedCells`] (cell averages and
/// conservative first collisions).
#[derive(Debug, Clone)]
pub struct Uncollided {
    /// `direct` on the problem.
    pub direct: Solution,
    /// The point-like lights (directional, point, spot), in the order of `cells`.
    pub lights: Vec<Light>,
    /// Per light, per extinction channel.
    pub cells: Vec<Vec<UncollidedCells>>,
    /// σ_t per extinction channel, as the integrals saw it.
    sigma_t: Vec<Grid>,
    /// Whether the rays bend (a graded index): a directional light's direction then
    /// changes from cell to cell.
    curved: bool,
}

impl Uncollided {
    /// Integrates the uncollided light of every light of `problem` (whose boundary must be
    /// vacuum: light travels in straight lines through its medium, which a caller masks to
    /// an embedded body first if it has one).
    ///
    /// Where the problem's refractive index is graded ([`Problem::has_graded_index`]) the
    /// light follows curved rays instead: see [`Uncollided::curved`].
    pub fn new(problem: &Problem, options: &SolveOptions) -> Result<Self, SolveError> {
        if problem.has_graded_index() {
            return Self::curved(problem, options);
        }
        // The deadline counts from now, before `direct` spends part of the budget.
        let interrupt = Interrupt::of(options);
        let direct = DirectSolver::default().solve(problem, options)?;
        let lights: Vec<Light> = problem
            .lights()
            .iter()
            .filter(|l| l.is_pointlike())
            .cloned()
            .collect();
        let sigma_t = problem.medium().sigma_t.clone();
        let cutoff = DirectSolver::default().max_optical_depth;
        let cells = options
            .install(|| {
                lights
                    .iter()
                    .map(|light| {
                        sigma_t
                            .iter()
                            .filter_map(|s| {
                                uncollided_cells_within(s, light, cutoff, &interrupt).transpose()
                            })
                            .collect::<Result<Vec<_>, Halt>>()
                    })
                    .collect::<Result<Vec<_>, Halt>>()
            })?
            .map_err(|halt| SolveError::Halted {
                solver: DirectSolver::NAME.into(),
                stage: "the uncollided light's cell integrals".into(),
                halt,
            })?;
        Ok(Self {
            direct,
            lights,
            cells,
            sigma_t,
            curved: false,
        })
    }

    /// The uncollided light along curved rays through a graded refractive index
    /// (`direct-refractive`, Bernabei ch. 4): its solution for the renderer, and per
    /// point-like light and cell the first collisions from the curved ray's arrival at
    /// the cell centre, C = σ_t E T V and D = C ω_arrival (E the ray tube's irradiance,
    /// T its transmittance, ω its direction on arrival).
    ///
    /// Unlike the straight rays' face rule this is a midpoint rule per cell, corrected for
    /// the attenuation across the cell (the centre's value times 2 sinh(x/2)/x, x = σ_t
    /// times the chord through the centre along the arrival direction: exact for a beam
    /// along an axis through a cell of constant σ_t): second order in h where σ_t and E
    /// are smooth, first order in the cells where τ has a kink (the surface swept by the
    /// rays that graze the box's edges), and not conservative by construction (a ray
    /// tube's flux is conserved to the tracer's tolerance, but a cell's share of it is
    /// sampled at one point). Near a point light, whose 1/r² the midpoint rule does not
    /// resolve, the cell holding it and its neighbours are off by tens of per cent, as the
    /// straight rays' point sampling was before the face rule. The books close through `escaped` = emitted − Σ C, with `emitted` the power
    /// the straight rays bring into the box (rays bend only inside it: η is continuous
    /// and equal outside to its value on the box's faces, so light enters where and as
    /// much as a straight ray would). The scattered light a solver adds to these sources
    /// diffuses or streams as in a uniform index: where η changes by a fraction δ over a
    /// transport mean free path, the equilibrium radiance's η² weighting it leaves out is
    /// an error of order 2δ in the scattered flux.
    pub fn curved(problem: &Problem, options: &SolveOptions) -> Result<Self, SolveError> {
        let direct =
            crate::refractive::DirectRefractiveSolver::default().solve(problem, options)?;
        let Some(Angular::Lights(transmittance)) = &direct.angular else {
            return Err(SolveError::InvalidParameter {
                name: "refractive_index".into(),
                reason: "direct-refractive kept no per-light transmittance".into(),
            });
        };
        let geometry = *problem.geometry();
        let volume = geometry.cell_volume();
        let h = volume.cbrt();
        let [nx, ny, _] = geometry.dims();
        let sigma_t = problem.medium().sigma_t.clone();
        let cutoff = DirectSolver::default().max_optical_depth;
        let kept: Vec<usize> = (0..transmittance.lights.len())
            .filter(|&l| transmittance.lights[l].is_pointlike())
            .collect();
        let lights: Vec<Light> = kept
            .iter()
            .map(|&l| transmittance.lights[l].clone())
            .collect();
        let cells = options.install(|| {
            kept.iter()
                .map(|&l| {
                    let grids = &transmittance.transmittance[l];
                    // The power the light brings into the box: σ_t plays no part in it.
                    let emitted = uncollided_cells(
                        &Grid::filled(geometry, 0.0),
                        &transmittance.lights[l],
                        cutoff,
                    )
                    .map_or(0.0, |straight| straight.emitted);
                    sigma_t
                        .iter()
                        .enumerate()
                        .map(|(c, s)| {
                            let t = &grids[c.min(grids.len() - 1)];
                            let (collided, (directed, fluence)): (
                                Vec<f64>,
                                (Vec<DVec3>, Vec<f64>),
                            ) = s
                                .data()
                                .par_iter()
                                .zip(t.data())
                                .enumerate()
                                .map(|(cell, (&sigma, &tr))| {
                                    let x = geometry.cell_centre(
                                        cell % nx,
                                        (cell / nx) % ny,
                                        cell / (nx * ny),
                                    );
                                    match transmittance.arrival(l, x) {
                                        Some((w, irradiance)) => {
                                            // The chord through the centre along the
                                            // arrival, h/max|ω_a|: the cell average of
                                            // e^{−σs} over it is the centre's times
                                            // 2 sinh(x/2)/x, x = σ_t × chord.
                                            let chord = h / w.abs().max_element().max(1e-12);
                                            let phi = irradiance
                                                * f64::from(tr)
                                                * chord_average(f64::from(sigma) * chord);
                                            let c = f64::from(sigma) * phi * volume;
                                            (c, (w * c, phi))
                                        }
                                        None => (0.0, (DVec3::ZERO, 0.0)),
                                    }
                                })
                                .unzip();
                            let total: f64 = collided.iter().sum();
                            UncollidedCells {
                                collided,
                                directed,
                                fluence,
                                emitted,
                                escaped: (emitted - total).max(0.0),
                            }
                        })
                        .collect()
                })
                .collect()
        })?;
        Ok(Self {
            direct,
            lights,
            cells,
            sigma_t,
            curved: true,
        })
    }

    /// The renderer's angular radiance of a solver that adds `scattered` fluence (per
    /// channel, taken) to this uncollided light: `direct`'s per-light transmittance for
    /// exact single scattering, and the scattered fluence plus the sky's uncollided fluence
    /// in-scattering isotropically (the lights' last channel serving any further ones).
    /// `None` when `direct` kept no transmittance.
    pub fn into_angular(self, scattered: &mut [Grid]) -> Option<Angular> {
        match self.direct.angular {
            Some(Angular::Lights(mut lights)) => {
                let last = lights.isotropic_fluence.len().saturating_sub(1);
                lights.isotropic_fluence = scattered
                    .iter_mut()
                    .enumerate()
                    .map(|(c, s)| {
                        let mut s = std::mem::replace(s, Grid::filled(*s.geometry(), 0.0));
                        if let Some(iso) = lights.isotropic_fluence.get(c.min(last)) {
                            for (a, b) in s.data_mut().iter_mut().zip(iso.data()) {
                                *a += b;
                            }
                        }
                        s
                    })
                    .collect();
                Some(Angular::Lights(lights))
            }
            // `direct` keeps per-light transmittance only.
            Some(Angular::Ordinates(_)) | None => None,
        }
    }

    /// The light's cell integrals in `channel`.
    fn cells_of(&self, light: usize, channel: usize) -> &UncollidedCells {
        let per_channel = &self.cells[light];
        &per_channel[channel.min(per_channel.len() - 1)]
    }

    /// The sky's uncollided fluence at cell centres in `channel` (zero without a sky).
    fn sky(&self, channel: usize) -> Option<&Grid> {
        match &self.direct.angular {
            Some(Angular::Lights(l)) => l
                .isotropic_fluence
                .get(channel.min(l.isotropic_fluence.len().saturating_sub(1))),
            _ => None,
        }
    }

    /// The cell-averaged uncollided fluence in `channel` (the sky's at cell centres).
    pub fn fluence(&self, channel: usize) -> Vec<f64> {
        let n = self.direct.fluence(channel).data().len();
        let mut phi = match self.sky(channel) {
            Some(sky) => sky.data().iter().map(|&v| f64::from(v)).collect(),
            None => vec![0.0; n],
        };
        for (l, light) in self.lights.iter().enumerate() {
            let scale = light.spectrum().channel(channel);
            for (p, u) in phi.iter_mut().zip(&self.cells_of(l, channel).fluence) {
                *p += scale * u;
            }
        }
        phi
    }

    /// The point-like lights' terms in a transport solver's energy balance in `channel`
    /// (W), for a solver whose swept source holds the scattered part of their first
    /// collisions: the power they bring into the box (or emit in it) less that scattered
    /// part (Σ C σ_s/σ_t over the cells, already counted as the source's), and the power
    /// that leaves the box uncollided. `sigma_s` holds σ_s per cell.
    pub fn balance_terms(&self, channel: usize, sigma_s: &[f32]) -> (f64, f64) {
        let sigma_t = self.sigma_t[channel.min(self.sigma_t.len() - 1)].data();
        let (mut entering, mut escaped) = (0.0, 0.0);
        for (light, cells) in self.lights.iter().zip(&self.cells) {
            let cells = &cells[channel.min(cells.len() - 1)];
            let scale = light.spectrum().channel(channel);
            let scattered: f64 = cells
                .collided
                .iter()
                .zip(sigma_t.iter().zip(sigma_s))
                .filter(|(_, (t, _))| **t > 0.0)
                .map(|(c, (t, s))| c * f64::from(*s) / f64::from(*t))
                .sum();
            entering += scale * (cells.emitted - scattered);
            escaped += scale * cells.escaped;
        }
        (entering, escaped)
    }

    /// The first-collision sources of a diffusion-type solver in `channel`, per cell:
    /// Q₀ = σ_s φ_u, isotropic (power/length³), with the point-like lights' part
    /// (σ_s/σ_t) C/V from their conservative cell integrals; and Q₁ = g (σ_s/σ_t) D/V, the
    /// first moment of once-scattered light for a phase function of mean cosine g (empty
    /// when g = 0 or no point-like light shines). `sigma_s` holds σ_s per cell.
    pub fn first_collision_sources(
        &self,
        channel: usize,
        sigma_s: &[f32],
        g: f64,
    ) -> (Vec<f32>, Vec<[f32; 3]>) {
        let sigma_t = self.sigma_t[channel.min(self.sigma_t.len() - 1)].data();
        let volume = self.direct.fluence(channel).geometry().cell_volume();
        let mut q0: Vec<f64> = match self.sky(channel) {
            Some(sky) => sky
                .data()
                .iter()
                .zip(sigma_s)
                .map(|(p, s)| f64::from(*p) * f64::from(*s))
                .collect(),
            None => vec![0.0; sigma_s.len()],
        };
        let moment = g != 0.0 && !self.lights.is_empty();
        let mut q1 = if moment {
            vec![DVec3::ZERO; sigma_s.len()]
        } else {
            Vec::new()
        };
        for (l, light) in self.lights.iter().enumerate() {
            let scale = light.spectrum().channel(channel) / volume;
            let cells = self.cells_of(l, channel);
            for cell in 0..q0.len() {
                if sigma_t[cell] <= 0.0 {
                    continue;
                }
                let albedo = f64::from(sigma_s[cell]) / f64::from(sigma_t[cell]);
                q0[cell] += scale * albedo * cells.collided[cell];
                if moment {
                    q1[cell] += cells.directed[cell] * (g * scale * albedo);
                }
            }
        }
        (
            q0.iter().map(|&v| v as f32).collect(),
            q1.iter().map(|v| v.as_vec3().to_array()).collect(),
        )
    }

    /// Projects the point-like lights' first collisions in `channel` onto a set of
    /// `directions` storage directions (what an angular method such as discrete ordinates
    /// or Lattice-Boltzmann needs): adds, per cell and direction m,
    /// (σ_s/σ_t)[(C − |D|)/4π + |D| p̄(D̂ → ω_m)]/V to `source[cell · directions + m]`,
    /// with C the power that first collides in the cell and D its direction-weighted
    /// integral ([`UncollidedCells`]), and `phase_from(D̂)` the method's discrete phase
    /// function from D̂ toward each storage direction (normalised as its scattering
    /// matrix is). The split keeps C and D exactly: the isotropic part carries no first
    /// moment (the light that reaches a cell from many directions, as in the cell holding
    /// a point light).
    pub fn project_first_collisions(
        &self,
        channel: usize,
        sigma_s: &[f32],
        directions: usize,
        phase_from: &(dyn Fn(DVec3) -> Vec<f64> + Sync),
        source: &mut [f32],
    ) {
        let m = directions;
        let sigma_t = self.sigma_t[channel.min(self.sigma_t.len() - 1)].data();
        let inv_volume = 1.0 / self.direct.fluence(channel).geometry().cell_volume();
        let isotropic = 1.0 / (4.0 * std::f64::consts::PI);
        // Directional lights have one direction everywhere (along straight rays): their
        // discrete phase once.
        let constant: Vec<Option<Vec<f64>>> = self
            .lights
            .iter()
            .map(|l| match l {
                Light::Directional { direction, .. } if !self.curved => {
                    Some(phase_from(*direction))
                }
                _ => None,
            })
            .collect();
        source
            .par_chunks_mut(m)
            .enumerate()
            .for_each(|(cell, row)| {
                if sigma_t[cell] <= 0.0 || sigma_s[cell] <= 0.0 {
                    return;
                }
                let scale = f64::from(sigma_s[cell]) / f64::from(sigma_t[cell]) * inv_volume;
                for (l, light) in self.lights.iter().enumerate() {
                    let cells = self.cells_of(l, channel);
                    let colour = light.spectrum().channel(channel);
                    let power = cells.collided[cell] * colour;
                    if power <= 0.0 {
                        continue;
                    }
                    let directed = cells.directed[cell] * colour;
                    let beam = directed.length().min(power);
                    let spread = (power - beam) * isotropic;
                    let local;
                    let phase = match &constant[l] {
                        Some(p) => p,
                        None if beam > 0.0 => {
                            local = phase_from(directed / directed.length());
                            &local
                        }
                        None => {
                            for v in row.iter_mut() {
                                *v += (scale * spread) as f32;
                            }
                            continue;
                        }
                    };
                    for (v, p) in row.iter_mut().zip(phase) {
                        *v += (scale * (spread + beam * p)) as f32;
                    }
                }
            });
    }
}
