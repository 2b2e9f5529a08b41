//! `direct-refractive`: uncollided light along curved rays through a graded refractive
//! index (Bernabei, thesis ch. 4, §4.2: single scattering in media of varying η).
//!
//! Rays obey the eikonal ray equation d/ds(η dx/ds) = ∇η ([`lucent_optics::eikonal`]:
//! RK4 with step doubling, error `tolerance` per unit length). Outside the grid's box
//! light travels in straight lines, and it crosses the box's faces without refraction
//! (the box is index-matched along each ray; a jump of η is a surface, for Fresnel and
//! Snell, which this solver does not model).
//!
//! **Aiming.** For each light and cell centre x the ray that reaches x is found by
//! shooting: a directional light's rays are labelled by their offset (a, b) across the
//! beam, a point or spot light's by the gnomonic coordinates (a, b) of their launch
//! direction about the straight line to x. Each ray is traced to the foot of x's
//! perpendicular on it, and Newton's method on (a, b), with the ray tube's Jacobian
//! ∂x/∂(a, b) ([`lucent_optics::eikonal::Tube`], the ray equation's variational
//! equations), drives the miss below `aim` cells. Each cell starts from its row
//! neighbour's ray (shifted by the straight lines' difference), so smooth fields converge
//! in one or two iterations. With a uniform η the first guess is the straight line and is
//! exact: no iteration runs.
//!
//! **Optical depth** is integrated exactly ([`Grid::line_integral`]) along the chords
//! between the tracer's nodes, at most one cell apart; the chords' sagitta, κh²/8 for a
//! ray of curvature κ = |∇η⊥|/η, is what separates them from the arc.
//!
//! **Flux.** A ray tube carries its flux unchanged (geometric optics: energy flows along
//! rays), so the irradiance normal to the ray at x is the flux entering the tube over its
//! cross-section at x: E = 1/|(∂x/∂a × ∂x/∂b)·t| for a directional light of unit
//! irradiance (a, b are lengths across the beam), E = I(ω) (dΩ/da db)/|(∂x/∂a × ∂x/∂b)·t|
//! for a point light of intensity I, dΩ/da db = |m|⁻³ for the gnomonic label
//! m = ω₀ + a e₁ + b e₂. The fluence the light leaves uncollided is E e^{−τ}. With uniform η
//! this is 1 and 1/r² to rounding: the solver then gives `direct`'s fluence. A point
//! light's E is capped at I/r_min² with `direct`'s r_min (half a cell).
//!
//! **The sky** is gathered backwards: from each cell centre along each quadrature
//! direction a ray is traced back out of the box; the radiance it brings is the sky's
//! times (η(x)/η_exit)², since L/η² is invariant along a ray.
//!
//! **Limits.** One ray per cell and light: where rays cross (past a caustic, as behind a
//! focusing lens) the fluence holds one branch, the one continued from the cell's row
//! neighbour or else the one Newton finds from the straight line, not the sum of all
//! branches. Cells that no ray reaches within 12 Newton iterations from those two starts
//! get no light from that light: a lens's true shadow (behind a Luneburg lens, beside its
//! focus, no ray arrives), and also cells that only a crossed branch reaches (behind the
//! focus, on the side where rows enter from the shadow). Cost: a traced ray per Newton iteration per cell and light, each
//! O(N) steps for N cells across: O(N⁴) like `direct`, with the ray equation's constant.

use glam::{DVec2, DVec3};
use lucent_grid::Grid;
use lucent_optics::eikonal::{
    EikonalError, IndexField, RayPoint, RaySettings, Tube, step_from, trace, trace_tube,
};
use rayon::prelude::*;

use crate::direct::{light_distances, sky_directions};
use crate::error::SolveError;
use crate::index::RefractiveIndex;
use crate::problem::{BoundaryKind, Light, LightKind, Problem};
use crate::registry::{Params, SolverEntry, SolverParams, param_docs, resolved_params};
use crate::solution::{Angular, CurvedArrival, LightTransmittance, Solution};
use crate::solver::{Capabilities, FluenceKind, OutputKind, Progress, SolveOptions, Solver};

/// The curved-ray uncollided-light solver; its fields are its registry parameters.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DirectRefractiveSolver {
    /// Refinement level of the octahedral sky quadrature (8·4^level directions).
    pub sky_level: usize,
    /// Optical depth at which a ray's integral stops.
    pub max_optical_depth: f64,
    /// The ray tracer's allowed error per unit length of path.
    pub tolerance: f64,
    /// How close (in cells) an aimed ray must pass a cell centre.
    pub aim: f64,
}

impl Default for DirectRefractiveSolver {
    fn default() -> Self {
        Self {
            sky_level: 1,
            max_optical_depth: 50.0,
            tolerance: 1e-9,
            aim: 1e-7,
        }
    }
}

impl SolverParams for DirectRefractiveSolver {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[
        (
            "sky_level",
            "octahedral sky quadrature level, 0 to 4 (8·4^level directions)",
        ),
        (
            "max_optical_depth",
            "optical depth (> 0) beyond which a ray's integral stops and light counts as gone",
        ),
        (
            "tolerance",
            "the ray tracer's local error per unit length of path, in (0, 1e-3]",
        ),
        (
            "aim",
            "how close an aimed ray must pass each cell centre, in cells, in (0, 0.1]",
        ),
    ];

    fn validate(&self) -> Result<(), SolveError> {
        let bad = |name: &str, reason: &str| SolveError::InvalidParameter {
            name: name.into(),
            reason: reason.into(),
        };
        if self.sky_level > 4 {
            return Err(bad("sky_level", "at most 4 (2048 directions)"));
        }
        if self.max_optical_depth.is_nan() || self.max_optical_depth <= 0.0 {
            return Err(bad("max_optical_depth", "must be positive"));
        }
        if !(self.tolerance > 0.0 && self.tolerance <= 1e-3) {
            return Err(bad("tolerance", "must be in (0, 1e-3]"));
        }
        if !(self.aim > 0.0 && self.aim <= 0.1) {
            return Err(bad("aim", "must be in (0, 0.1] cells"));
        }
        Ok(())
    }
}

impl DirectRefractiveSolver {
    /// The registry name.
    pub const NAME: &'static str = "direct-refractive";

    /// The registry entry.
    pub const ENTRY: SolverEntry = SolverEntry {
        name: Self::NAME,
        summary: "uncollided light along curved rays through a graded refractive index (eikonal rays, flux by ray tubes)",
        build: |params| Ok(Box::new(Self::from_params(params)?)),
        params: param_docs::<Self>,
        resolved: |p| resolved_params::<Self>(p, Self::NAME),
    };

    /// Builds from registry parameters.
    pub fn from_params(params: &Params) -> Result<Self, SolveError> {
        params.parse(Self::NAME)
    }
}

impl Solver for DirectRefractiveSolver {
    fn name(&self) -> &str {
        Self::NAME
    }

    fn capabilities(&self) -> Capabilities {
        Capabilities {
            anisotropic: true,
            heterogeneous: true,
            graded_index: true,
            boundaries: vec![BoundaryKind::Vacuum],
            lights: vec![
                LightKind::Directional,
                LightKind::Point,
                LightKind::Spot,
                LightKind::Sky,
            ],
            output: OutputKind::AngularRadiance,
            fluence: FluenceKind::Uncollided,
            ..Capabilities::default()
        }
    }

    fn solve(&self, problem: &Problem, options: &SolveOptions) -> Result<Solution, SolveError> {
        self.validate()?;
        let geometry = *problem.geometry();
        let channels = problem.channels();
        let extinction = problem.medium().sigma_t.len();
        let (point_lights, sky): (Vec<&Light>, Vec<&Light>) = problem
            .lights()
            .iter()
            .partition(|l| !matches!(l, Light::Sky { .. }));
        // Per point-like light: irradiance, three direction components and the
        // transmittance per extinction channel; per channel isotropic fluence and fluence.
        let grid_bytes = geometry.voxel_count() as u64 * 4;
        let needed = grid_bytes * (point_lights.len() * (4 + extinction) + 2 * channels + 1) as u64;
        crate::driver::run(self, problem, options, needed, |context| {
            self.transport(context, &point_lights, &sky, needed)
        })
    }
}

/// A ray error as the solver's.
fn ray_error(e: EikonalError) -> SolveError {
    SolveError::InvalidParameter {
        name: "refractive_index".into(),
        reason: e.to_string(),
    }
}

/// The tracing context of one problem.
struct Tracer<'a> {
    index: &'a dyn IndexField,
    sigma_t: &'a [Grid],
    lo: DVec3,
    hi: DVec3,
    /// The smallest cell side (length).
    cell: f64,
    settings: RaySettings,
    /// Arc length beyond which a ray is given up (it is still in the box: trapped).
    max_length: f64,
    cutoff: f64,
    aim: f64,
}

/// A ray from its entry into the box (or its source inside it) to where it stopped: the
/// nodes it passed (the chords' ends, the first being the start) and its last point.
struct Traced {
    nodes: Vec<DVec3>,
    end: RayPoint,
}

/// Where a launched ray starts inside the box: position, unit direction, tube.
struct Launch {
    start: DVec3,
    direction: DVec3,
    tube: Tube,
}

impl Tracer<'_> {
    fn inside(&self, x: DVec3, slack: f64) -> bool {
        x.cmpge(self.lo - slack).all() && x.cmple(self.hi + slack).all()
    }

    /// Where the line p + λ d (λ ≥ `from`) enters the box: λ and the axis of the face it
    /// crosses (`None` when p is already inside), or `None` if it misses the box.
    fn entry(&self, p: DVec3, d: DVec3, from: f64) -> Option<(f64, Option<usize>)> {
        let (mut near, mut far, mut axis) = (from, f64::INFINITY, None);
        for a in 0..3 {
            if d[a] == 0.0 {
                if p[a] < self.lo[a] || p[a] > self.hi[a] {
                    return None;
                }
                continue;
            }
            let (t0, t1) = ((self.lo[a] - p[a]) / d[a], (self.hi[a] - p[a]) / d[a]);
            let (t0, t1) = (t0.min(t1), t0.max(t1));
            if t0 > near {
                near = t0;
                axis = Some(a);
            }
            far = far.min(t1);
        }
        (near <= far).then_some((near, axis))
    }

    /// A ray family's member entering the box: the straight line p + λ d with ∂p/∂aᵢ =
    /// `dp`, ∂d/∂aᵢ = `dd`, continued into the box with v = η d and the tube it starts
    /// with there (the entry point slides along the face it crosses).
    fn launch(&self, p: DVec3, d: DVec3, dp: [DVec3; 2], dd: [DVec3; 2]) -> Option<Launch> {
        let (lambda, axis) = self.entry(p, d, 0.0)?;
        let start = p + d * lambda;
        let eta = self.index.eta(start);
        let gradient = self.index.gradient(start);
        let dx = |i: usize| {
            let along = dp[i] + dd[i] * lambda;
            // The face x_k = const: ∂λ/∂aᵢ = −(∂(p + λ d)_k/∂aᵢ at fixed λ)/d_k.
            match axis {
                Some(k) => along - d * (along[k] / d[k]),
                None => along,
            }
        };
        let dx = [dx(0), dx(1)];
        let dv = |i: usize| dd[i] * eta + d * gradient.dot(dx[i]);
        Some(Launch {
            start,
            direction: d,
            tube: Tube {
                dx,
                dv: [dv(0), dv(1)],
            },
        })
    }

    /// Traces `launch` until it reaches the foot of `target`'s perpendicular on it (landing
    /// there exactly), leaves the box, or runs out of length.
    fn trace_to(&self, launch: &Launch, target: DVec3) -> Result<Traced, SolveError> {
        let along = |p: &RayPoint| (p.position - target).dot(p.direction);
        let mut nodes = Vec::new();
        let mut last: Option<RayPoint> = None;
        let mut passed: Option<RayPoint> = None;
        let slack = 1e-9 * self.cell;
        trace_tube(
            self.index,
            launch.start,
            launch.direction,
            launch.tube,
            self.max_length,
            &self.settings,
            |p| {
                if along(p) >= 0.0 {
                    passed = Some(*p);
                    return false;
                }
                nodes.push(p.position);
                last = Some(*p);
                self.inside(p.position, slack)
            },
        )
        .map_err(ray_error)?;
        let end = match (last, passed) {
            // Beyond the foot from the start: the foot lies on the straight line before the
            // box (or behind the source).
            (None, Some(p)) => {
                nodes.push(p.position);
                RayPoint {
                    position: p.position - p.direction * along(&p),
                    ..p
                }
            }
            // The foot between the last two points: land on it by secant steps.
            (Some(prev), Some(next)) => {
                let (mut h0, mut f0) = (0.0, along(&prev));
                let (mut h1, mut f1) = (next.arc_length - prev.arc_length, along(&next));
                let mut landed = next;
                for _ in 0..4 {
                    let h = h0 + (h1 - h0) * (-f0) / (f1 - f0);
                    landed =
                        step_from(self.index, &prev, h, true, &self.settings).map_err(ray_error)?;
                    let f = along(&landed);
                    if f.abs() <= 1e-12 * self.cell {
                        break;
                    }
                    if f < 0.0 {
                        (h0, f0) = (h, f);
                    } else {
                        (h1, f1) = (h, f);
                    }
                }
                landed
            }
            (Some(prev), None) => prev,
            (None, None) => unreachable!("the tracer visits its start"),
        };
        Ok(Traced { nodes, end })
    }

    /// τ per extinction channel along `nodes` then `end`.
    fn optical_depths(&self, nodes: &[DVec3], end: DVec3) -> Vec<f64> {
        self.sigma_t
            .iter()
            .map(|sigma_t| {
                let mut tau = 0.0;
                let mut from = nodes[0];
                for &to in nodes[1..].iter().chain(std::iter::once(&end)) {
                    tau += sigma_t.line_integral(from, to, (self.cutoff - tau).max(0.0));
                    if tau >= self.cutoff {
                        break;
                    }
                    from = to;
                }
                tau
            })
            .collect()
    }
}

/// What one light delivers at one cell centre.
#[derive(Clone)]
struct Arrival {
    /// Irradiance normal to the ray per unit of the light's spectrum and emission (the
    /// ray tube's spreading; a point light's capped as `direct` caps its 1/r²).
    spreading: f64,
    /// The light's relative emission toward the launch direction (1 but for spots).
    emission: f64,
    /// Direction of travel on arrival.
    direction: DVec3,
    /// Launch direction (a point light's; the beam's direction for directional lights).
    launch: DVec3,
    tau: Vec<f64>,
    /// The converged ray's label (a, b), a start for the next cell.
    label: DVec2,
}

/// A point-like light's family of rays, labelled by (a, b).
enum Family {
    /// Parallel rays along `direction`, offset a e₁ + b e₂ from the box's centre.
    Beam {
        direction: DVec3,
        centre: DVec3,
        e: [DVec3; 2],
    },
    /// Rays from `position` in the directions m/|m|, m = ω₀ + a e₁ + b e₂.
    Fan {
        position: DVec3,
        axis: DVec3,
        e: [DVec3; 2],
    },
}

/// Two unit vectors completing `d` to a right-handed orthonormal frame.
fn frame(d: DVec3) -> [DVec3; 2] {
    let (a, b) = d.any_orthonormal_pair();
    // any_orthonormal_pair is right-handed: a × b = d.
    [a, b]
}

impl Family {
    fn launch(&self, tracer: &Tracer<'_>, label: DVec2) -> Option<Launch> {
        match *self {
            Family::Beam {
                direction,
                centre,
                e,
            } => {
                let p = centre + e[0] * label.x + e[1] * label.y - direction * tracer.max_length;
                tracer.launch(p, direction, e, [DVec3::ZERO; 2])
            }
            Family::Fan { position, axis, e } => {
                let m = axis + e[0] * label.x + e[1] * label.y;
                let w = m / m.length();
                let dw = e.map(|ei| (ei - w * w.dot(ei)) / m.length());
                tracer.launch(position, w, [DVec3::ZERO; 2], dw)
            }
        }
    }

    /// The launch direction of ray `label` and its flux per unit of (a, b) per unit of
    /// emission: 1 across a beam, dΩ/da db = |m|⁻³ for a fan.
    fn launch_direction(&self, label: DVec2) -> (DVec3, f64) {
        match *self {
            Family::Beam { direction, .. } => (direction, 1.0),
            Family::Fan { axis, e, .. } => {
                let m = axis + e[0] * label.x + e[1] * label.y;
                (m / m.length(), m.length().powi(-3))
            }
        }
    }
}

/// The label of the straight line to `x` in `family` (a fan's frame is about it: zero).
fn straight_label(family: &Family, x: DVec3) -> DVec2 {
    match *family {
        Family::Beam { centre, e, .. } => {
            DVec2::new((x - centre).dot(e[0]), (x - centre).dot(e[1]))
        }
        Family::Fan { .. } => DVec2::ZERO,
    }
}

/// Shoots rays of `family` at `target` from `guess`: the arrival, or `None` when no ray
/// lands within the aim.
fn aim_at(
    tracer: &Tracer<'_>,
    light: &Light,
    family: &Family,
    target: DVec3,
    guess: DVec2,
) -> Result<Option<Arrival>, SolveError> {
    let tolerance = tracer.aim * tracer.cell;
    let shoot = |label: DVec2| -> Result<Option<(Traced, DVec3)>, SolveError> {
        let Some(launch) = family.launch(tracer, label) else {
            return Ok(None);
        };
        let traced = tracer.trace_to(&launch, target)?;
        let miss = traced.end.position - target;
        Ok(Some((traced, miss)))
    };
    let mut label = guess;
    let Some(mut current) = shoot(label)? else {
        return Ok(None);
    };
    for _ in 0..12 {
        let (traced, miss) = &current;
        if miss.length() <= tolerance {
            let t = traced.end.direction;
            let section = traced.end.tube.cross_section(t).abs();
            let (launch, flux) = family.launch_direction(label);
            let spreading = if section > 0.0 { flux / section } else { 0.0 };
            // A point light's spreading is capped as `direct` caps its 1/r².
            let spreading = match family {
                Family::Fan { .. } => spreading.min(1.0 / (0.5 * tracer.cell).powi(2)),
                Family::Beam { .. } => spreading,
            };
            return Ok(Some(Arrival {
                spreading,
                emission: light.emission_toward(launch),
                direction: t,
                launch,
                tau: tracer.optical_depths(&traced.nodes, traced.end.position),
                label,
            }));
        }
        // Newton on the miss across the ray: J = ∂x/∂(a, b) projected on a frame ⟂ t.
        let t = traced.end.direction;
        let q = frame(t);
        let j = traced.end.tube.dx;
        let (a11, a12, a21, a22) = (
            q[0].dot(j[0]),
            q[0].dot(j[1]),
            q[1].dot(j[0]),
            q[1].dot(j[1]),
        );
        let det = a11 * a22 - a12 * a21;
        if det == 0.0 || !det.is_finite() {
            return Ok(None);
        }
        let (r1, r2) = (q[0].dot(*miss), q[1].dot(*miss));
        let step = DVec2::new(-(a22 * r1 - a12 * r2) / det, -(-a21 * r1 + a11 * r2) / det);
        // Damped: halve the step until the miss shrinks.
        let mut scale = 1.0;
        let mut improved = None;
        for _ in 0..8 {
            let trial = label + step * scale;
            if let Some(next) = shoot(trial)?
                && next.1.length() < miss.length()
            {
                improved = Some((trial, next));
                break;
            }
            scale *= 0.5;
        }
        let Some((trial, next)) = improved else {
            return Ok(None);
        };
        label = trial;
        current = next;
    }
    Ok(None)
}

impl DirectRefractiveSolver {
    /// The uncollided light of `point_lights` and `sky` along curved rays.
    fn transport(
        &self,
        context: &crate::driver::Context<'_>,
        point_lights: &[&Light],
        sky: &[&Light],
        needed: u64,
    ) -> Result<crate::driver::Outcome, SolveError> {
        let problem = context.problem;
        let geometry = *problem.geometry();
        let [nx, ny, nz] = geometry.dims();
        let medium = problem.medium();
        let channels = problem.channels();
        let unit = RefractiveIndex::Uniform(1.0);
        let index: &dyn IndexField = problem.refractive_index().unwrap_or(&unit);
        let (lo, hi) = geometry.bounds();
        let cell = geometry.spacing().min_element();
        let diagonal = (hi - lo).length();
        let tracer = Tracer {
            index,
            sigma_t: &medium.sigma_t,
            lo,
            hi,
            cell,
            settings: RaySettings {
                tolerance: self.tolerance,
                max_step: cell,
                min_step: 1e-9 * cell,
            },
            max_length: 4.0 * diagonal + cell,
            cutoff: self.max_optical_depth,
            aim: self.aim,
        };
        let (far, min_distance) = light_distances(problem);
        let work = (point_lights.len() + usize::from(!sky.is_empty())) as f64;
        let mut done = 0.0;
        let extinction = medium.sigma_t.len();
        let interrupt = context.interrupt();

        let mut arrivals = Vec::with_capacity(point_lights.len());
        let mut irradiances: Vec<Vec<f64>> = Vec::with_capacity(point_lights.len());
        let mut per_light = Vec::with_capacity(point_lights.len());
        for light in point_lights {
            let centre = 0.5 * (lo + hi);
            let mut focusing = Grid::filled(geometry, 0.0);
            let mut bend = [(); 3].map(|_| Grid::filled(geometry, 0.0));
            let mut launch_bend = [(); 3].map(|_| Grid::filled(geometry, 0.0));
            let mut irradiance = vec![0.0f64; geometry.voxel_count()];
            let mut transmittance: Vec<Grid> = (0..extinction)
                .map(|_| Grid::filled(geometry, 0.0))
                .collect();
            // Rows of cells (x fastest), each row aimed in order from its neighbours.
            let rows: Vec<Vec<Arrival>> = (0..ny * nz)
                .into_par_iter()
                .map(|row| -> Result<Vec<Arrival>, SolveError> {
                    interrupt.check(Self::NAME, "curved rays from a light")?;
                    let (j, k) = (row % ny, row / ny);
                    let mut out = Vec::with_capacity(nx);
                    let mut previous: Option<(DVec3, DVec2)> = None;
                    for i in 0..nx {
                        let x = geometry.cell_centre(i, j, k);
                        let arrival = match **light {
                            Light::Directional { direction, .. } => {
                                let family = Family::Beam {
                                    direction,
                                    centre,
                                    e: frame(direction),
                                };
                                let guess = match previous {
                                    Some((px, label)) => {
                                        label + straight_label(&family, x)
                                            - straight_label(&family, px)
                                    }
                                    None => straight_label(&family, x),
                                };
                                match aim_at(&tracer, light, &family, x, guess)? {
                                    // The neighbour's branch may not reach this cell;
                                    // the straight line's may.
                                    None if previous.is_some() => aim_at(
                                        &tracer,
                                        light,
                                        &family,
                                        x,
                                        straight_label(&family, x),
                                    )?,
                                    found => found,
                                }
                            }
                            Light::Point { position, .. } | Light::Spot { position, .. } => {
                                fan_arrival(&tracer, light, position, x, previous, min_distance)?
                            }
                            Light::Sky { .. } | Light::Emission { .. } => None,
                        };
                        let reached = arrival.is_some();
                        let arrival = arrival.unwrap_or(Arrival {
                            spreading: 0.0,
                            emission: 0.0,
                            direction: DVec3::ZERO,
                            launch: DVec3::ZERO,
                            tau: vec![f64::INFINITY; extinction],
                            label: DVec2::ZERO,
                        });
                        previous = reached.then_some((x, arrival.label));
                        out.push(arrival);
                    }
                    Ok(out)
                })
                .collect::<Result<_, _>>()?;
            for (row, cells) in rows.iter().enumerate() {
                for (i, a) in cells.iter().enumerate() {
                    let index = i + nx * row;
                    let x = geometry.cell_centre(i, row % ny, row / ny);
                    // The straight line's direction and spreading, as `direct` has them.
                    let (w, _, _) = light
                        .arrival(x, far, min_distance)
                        .expect("point-like lights arrive from one direction");
                    let straight = light.spreading(x, min_distance);
                    irradiance[index] = a.emission * a.spreading;
                    focusing.data_mut()[index] = (a.spreading / straight) as f32;
                    for c in 0..3 {
                        if a.spreading > 0.0 {
                            bend[c].data_mut()[index] = (a.direction[c] - w[c]) as f32;
                            if matches!(**light, Light::Point { .. } | Light::Spot { .. }) {
                                launch_bend[c].data_mut()[index] = (a.launch[c] - w[c]) as f32;
                            }
                        }
                    }
                    for (g, tau) in transmittance.iter_mut().zip(&a.tau) {
                        g.data_mut()[index] = (-tau).exp() as f32;
                    }
                }
            }
            arrivals.push(CurvedArrival {
                focusing,
                bend,
                launch_bend,
            });
            irradiances.push(irradiance);
            per_light.push(transmittance);
            done += 1.0;
            context.report(Progress {
                stage: "curved light transmittance",
                fraction: done / work,
                iteration: 0,
                residual: None,
            });
        }

        // The sky, gathered backwards: Σ_d w_d (η(x)/η_exit)² e^{−τ_d} per extinction channel.
        let sky_transmittance: Option<Vec<Grid>> = if sky.is_empty() {
            None
        } else {
            let directions = sky_directions(self.sky_level)?;
            let sums: Vec<Vec<f64>> = (0..nx * ny * nz)
                .into_par_iter()
                .map(|cell_index| -> Result<Vec<f64>, SolveError> {
                    interrupt.check(Self::NAME, "curved rays from the sky")?;
                    let (i, j, k) = (
                        cell_index % nx,
                        (cell_index / nx) % ny,
                        cell_index / (nx * ny),
                    );
                    let x = geometry.cell_centre(i, j, k);
                    let eta_here = index.eta(x);
                    let mut total = vec![0.0; extinction];
                    for &(d, w) in &directions {
                        let mut nodes = Vec::new();
                        let end = trace(index, x, -d, tracer.max_length, &tracer.settings, |p| {
                            nodes.push(p.position);
                            tracer.inside(p.position, 0.0)
                        })
                        .map_err(ray_error)?;
                        let last = nodes.pop().unwrap_or(end.position);
                        if nodes.is_empty() {
                            nodes.push(x);
                        }
                        // Where the last chord leaves the box: the sky's radiance enters
                        // there with η of that point.
                        let inner = nodes[nodes.len() - 1];
                        let back = (inner - last).normalize_or_zero();
                        let exit = match tracer.entry(last, back, 0.0) {
                            Some((lambda, _)) if back != DVec3::ZERO => last + back * lambda,
                            _ => inner,
                        };
                        let gain = (eta_here / index.eta(exit)).powi(2);
                        let taus = tracer.optical_depths(&nodes, last);
                        for (t, tau) in total.iter_mut().zip(taus) {
                            *t += w * gain * (-tau).exp();
                        }
                    }
                    Ok(total)
                })
                .collect::<Result<_, _>>()?;
            context.report(Progress {
                stage: "sky transmittance",
                fraction: 1.0,
                iteration: 0,
                residual: None,
            });
            Some(
                (0..extinction)
                    .map(|c| {
                        let mut g = Grid::filled(geometry, 0.0);
                        for (v, s) in g.data_mut().iter_mut().zip(&sums) {
                            *v = s[c] as f32;
                        }
                        g
                    })
                    .collect(),
            )
        };

        // Fluence per channel: E_l T_l summed over the lights, plus the sky.
        let sky_radiance: Vec<f64> = (0..channels)
            .map(|c| sky.iter().map(|l| l.spectrum().channel(c)).sum())
            .collect();
        let isotropic_fluence: Vec<Grid> = (0..channels)
            .map(|c| match &sky_transmittance {
                Some(t) => t[c.min(t.len() - 1)].map(|v| (f64::from(v) * sky_radiance[c]) as f32),
                None => Grid::filled(geometry, 0.0),
            })
            .collect();
        let fluence: Vec<Grid> = (0..channels)
            .map(|c| {
                let mut phi = isotropic_fluence[c].clone();
                for (l, light) in point_lights.iter().enumerate() {
                    let colour = light.spectrum().channel(c);
                    let t = &per_light[l][c.min(extinction - 1)];
                    for ((p, e), t) in phi.data_mut().iter_mut().zip(&irradiances[l]).zip(t.data())
                    {
                        *p = (f64::from(*p) + colour * e * f64::from(*t)) as f32;
                    }
                }
                phi
            })
            .collect();
        Ok(crate::driver::Outcome {
            fluence,
            angular: Some(Angular::Lights(LightTransmittance {
                phase: medium.phase,
                lights: point_lights.iter().map(|&l| l.clone()).collect(),
                transmittance: per_light,
                far,
                min_distance,
                isotropic_fluence,
                arrivals,
            })),
            standard_error: None,
            record: crate::driver::Record::exact(needed),
        })
    }
}

/// A point or spot light's arrival at `x`: aimed from the previous cell's launch direction
/// shifted by the straight lines' turn, in a frame about the straight line to `x`. A cell
/// centre on the light itself gets `direct`'s value (the capped 1/r², no attenuation).
fn fan_arrival(
    tracer: &Tracer<'_>,
    light: &Light,
    position: DVec3,
    x: DVec3,
    previous: Option<(DVec3, DVec2)>,
    min_distance: f64,
) -> Result<Option<Arrival>, SolveError> {
    let to = x - position;
    if to.length() <= 1e-12 * tracer.cell {
        let w = match *light {
            Light::Spot { direction, .. } => direction,
            _ => DVec3::Z,
        };
        return Ok(Some(Arrival {
            spreading: 1.0 / (min_distance * min_distance).max(1e-300),
            emission: light.emission_toward(w),
            direction: w,
            launch: w,
            tau: vec![0.0; tracer.sigma_t.len()],
            label: DVec2::ZERO,
        }));
    }
    let axis = to / to.length();
    let e = frame(axis);
    let family = Family::Fan { position, axis, e };
    // The previous cell's launch direction, turned as the straight line turned, in this
    // cell's gnomonic coordinates. The label kept per cell is the launch direction's.
    let guess = match previous {
        Some((px, launched)) => {
            let before = (px - position).normalize_or_zero();
            let w = spherical_to_vec(launched) + axis - before;
            if w.dot(axis) > 0.0 {
                let m = w / w.dot(axis);
                DVec2::new(m.dot(e[0]), m.dot(e[1]))
            } else {
                DVec2::ZERO
            }
        }
        None => DVec2::ZERO,
    };
    let arrival = match aim_at(tracer, light, &family, x, guess)? {
        // The neighbour's branch may not reach this cell; the straight line's may.
        None if previous.is_some() => aim_at(tracer, light, &family, x, DVec2::ZERO)?,
        found => found,
    };
    // Keep the launch direction (as two spherical angles) for the next cell's guess.
    Ok(arrival.map(|mut a| {
        let m = axis + e[0] * a.label.x + e[1] * a.label.y;
        a.label = vec_to_spherical(m / m.length());
        a
    }))
}

/// A unit vector as (polar, azimuth) angles and back (the fan's remembered launch
/// direction).
fn vec_to_spherical(w: DVec3) -> DVec2 {
    DVec2::new(w.z.clamp(-1.0, 1.0).acos(), w.y.atan2(w.x))
}

fn spherical_to_vec(angles: DVec2) -> DVec3 {
    let (theta, phi) = (angles.x, angles.y);
    DVec3::new(
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    )
}
