//! The lattice march to steady state on a box: collision, streaming (in place by the AA
//! pattern, or between two arrays), boundaries, sources, the stopping test and the energy
//! bookkeeping. Lattice units throughout: one cell is one lattice spacing and one step.

use lucent_core::{History, StopReason, Stopping};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::LbmError;
use crate::lattice::{Links, Velocities};

/// What happens to absorbed light.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Absorption {
    /// It leaves: a sink of κ_a ρ per step (σ_a per unit length).
    #[default]
    True,
    /// Bernabei's and Geist's collision matrices as printed (with the sign of Geist's
    /// diagonal corrected): the absorbed fraction moves to the rest population and is
    /// re-emitted at the next step, so energy is conserved and κ_a only slows diffusion.
    Thesis,
}

/// The collision operator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Collision {
    /// Two relaxation times: odd moments (the flux) relax at ω⁻, set so that the lattice's
    /// diffusion coefficient c_s²(1/ω⁻ − ½) is the medium's D = 1/(3σ_t′) (the phase
    /// function enters through σ_t′ = σ_a + (1 − g)σ_s); even moments at ω⁺ with
    /// Λ = (1/ω⁺ − ½)(1/ω⁻ − ½) = ¼, which puts the walls' conditions at the half-links.
    #[default]
    Trt,
    /// One relaxation time ω⁺ = ω⁻ (BGK) from the same D: the walls' conditions then sit at
    /// a distance from the half-link that depends on ω (first order at the walls).
    Bgk,
    /// Geist et al.'s physical probabilities per step: κ_t = 1 − e^{−σ_t h} interacting,
    /// κ_s = albedo κ_t scattering isotropically (the transport approximation for g ≠ 0:
    /// κ_s(1 − g), κ_t − gκ_s), the rest population as the thesis has it. Its D is
    /// h(2/κ_t − 1)/(6(1 + κ_a)) (D3Q7, Bernabei) or h(2/κ_t − 1)/(4(1 + κ_a)) (D3Q19,
    /// Geist), first order in h against 1/(3σ_t′).
    Geist,
}

/// The streaming pattern.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Streaming {
    /// One array of populations (Bailey et al.'s AA pattern): even steps collide in place
    /// into the opposite slots, odd steps read from and write to the neighbours' slots.
    #[default]
    InPlace,
    /// Two arrays: read one, write the other (twice the memory).
    TwoArrays,
}

/// A box's wall condition, in lattice units: the fluence at the half-link ρ_w relates to
/// the outward flux J_n through the wall.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Wall {
    /// ρ_w = 2A J_n (Robin; a vacuum is A from the Milne problem).
    Robin {
        /// The boundary factor A ≥ 1.
        a: f64,
    },
    /// ρ_w given.
    Dirichlet {
        /// Fluence at the wall.
        value: f64,
    },
    /// J_n given (0: reflecting).
    Neumann {
        /// Outward flux per unit area per step.
        flux: f64,
    },
    /// The physical wall of Geist's and Bernabei's lattices: a fraction `reflectance` of
    /// the light leaving along a link comes back along its opposite, the rest leaves
    /// (0: a vacuum, nothing enters; a Robin interface's diffuse reflectance).
    Reflect {
        /// Fraction sent back, in [0, 1].
        reflectance: f64,
    },
}

/// A problem on the lattice: per cell coefficients and sources in lattice units.
#[derive(Debug, Clone, PartialEq)]
pub struct LatticeProblem {
    /// Cells along x, y, z.
    pub dims: [usize; 3],
    /// `Trt`/`Bgk`: D/h per cell. `Geist`: κ_t per cell.
    pub first: Vec<f32>,
    /// `Trt`/`Bgk`: κ_a = σ_a h per cell. `Geist`: κ_s per cell.
    pub second: Vec<f32>,
    /// Isotropic source per step (q₀ h: fluence per step).
    pub source: Vec<f32>,
    /// First moment of the source per step (q₁ h), or empty.
    pub first_moment: Vec<[f32; 3]>,
    /// The walls' condition.
    pub wall: Wall,
}

/// How to march.
#[derive(Debug, Clone, PartialEq)]
pub struct MarchSettings {
    /// The velocity set.
    pub velocities: Velocities,
    /// The collision operator.
    pub collision: Collision,
    /// What absorption does.
    pub absorption: Absorption,
    /// The streaming pattern.
    pub streaming: Streaming,
    /// When to stop: the residual is the larger of the relative change of the fluence in
    /// one step, ‖ρ′ − ρ‖/‖ρ′‖, and the energy imbalance per step,
    /// |emitted − absorbed − escaped| / max(emitted, absorbed + |escaped|).
    pub stopping: Stopping,
    /// Bernabei's blockwise scheduling (`None`: every cell steps together).
    pub blocks: Option<Blocks>,
}

/// Blockwise scheduling (Bernabei ch. 4, after the GPU's texture-sized blocks): the volume
/// is cut into blocks of `slabs` z-slabs, advanced in turn, each by `steps_per_visit`
/// steps while the others wait; a block streams in what its neighbours last left (a
/// neighbour visited earlier in the sweep has already moved on: a Gauss–Seidel-like
/// order). One iteration of the march is one sweep over the blocks. The steady state is
/// the synchronous lattice's (the same fixed point), but the transient is not a physical
/// time history: a population crossing a block's face can be skipped or repeated, so the
/// energy books balance only at convergence. Needs two arrays of populations.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Blocks {
    /// z-slabs per block (≥ 1).
    pub slabs: usize,
    /// Steps a block takes per visit (≥ 1).
    pub steps_per_visit: usize,
}

/// The energy bookkeeping of a march (lattice units: fluence × cell volume).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Bookkeeping {
    /// Emitted by the sources over the march.
    pub emitted: f64,
    /// Absorbed over the march (0 for the thesis's absorption).
    pub absorbed: f64,
    /// Net outflow through the walls over the march.
    pub escaped: f64,
    /// What the lattice holds at the end.
    pub held: f64,
    /// Per step at the end (the mean of the last two steps): emitted, absorbed and escaped
    /// (the steady-state balance).
    pub rates: [f64; 3],
}

impl Bookkeeping {
    /// |emitted − absorbed − escaped − held| over the largest of emitted and
    /// absorbed + |escaped| (a wall's inflow is a negative escape): the lattice conserves
    /// energy, so this is rounding only.
    pub fn conservation_error(&self) -> f64 {
        let scale = self.emitted.max(self.absorbed + self.escaped.abs());
        (self.emitted - self.absorbed - self.escaped - self.held).abs() / scale.max(1e-300)
    }

    /// |emitted − absorbed − escaped| per step at the end, over the larger side: how far
    /// from steady.
    pub fn steady_imbalance(&self) -> f64 {
        let [e, a, x] = self.rates;
        (e - a - x).abs() / e.max(a + x.abs()).max(1e-300)
    }
}

/// The energy books and the residual of a march, step by step: what the CPU lattice and
/// its device twin (`gpu-lbm`) share, so both stop by one rule.
///
/// The residual of a step is the larger of the relative change of the fluence,
/// ‖ρ′ − ρ‖/‖ρ′‖, and the energy imbalance per step (the mean of the last two steps'
/// emitted, absorbed and escaped light: the AA pattern answers an even step's walls in
/// the odd step after it, so one step's escape alone alternates).
#[derive(Debug, Clone)]
pub struct Ledger {
    book: Bookkeeping,
    previous: [f64; 3],
    steps: usize,
    emitted_per_step: f64,
    shines: bool,
}

impl Ledger {
    /// The books of a march of `problem` from zero.
    pub fn new(problem: &LatticeProblem, settings: &MarchSettings) -> Self {
        let collider = Collider::new(settings);
        // Emitted per step: Σ_i s_i over the cells (the first moment's part sums to 0).
        let w_sum: f64 = collider.source_w.iter().map(|&w| f64::from(w)).sum();
        // One iteration of a blockwise march advances every cell `steps_per_visit` steps.
        let steps_per_iteration = settings.blocks.map_or(1, |b| b.steps_per_visit) as f64;
        let emitted_per_step: f64 =
            problem.source.iter().map(|&s| f64::from(s)).sum::<f64>() * w_sum * steps_per_iteration;
        // Before any light has reached a cell the relative change is undefined: not
        // converged, unless nothing shines at all (the zero field is the solution).
        let shines = emitted_per_step != 0.0
            || matches!(problem.wall, Wall::Dirichlet { value } if value != 0.0)
            || matches!(problem.wall, Wall::Neumann { flux } if flux != 0.0);
        Self {
            book: Bookkeeping::default(),
            previous: [0.0; 3],
            steps: 0,
            emitted_per_step,
            shines,
        }
    }

    /// Steps recorded.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// Records one step's absorbed and escaped light and its Σ(ρ′ − ρ)² and Σρ′² (f64
    /// sums over the cells); returns the step's (relative, absolute) residual for
    /// [`History::record_step`]: the relative one is the larger of the change and the
    /// imbalance (the change alone stalls near 2e-7, f32 rounding, while the lattice
    /// still fills slowly; the imbalance says how far from steady it is in energy).
    pub fn step(&mut self, absorbed: f64, escaped: f64, change: f64, size: f64) -> (f64, f64) {
        self.steps += 1;
        self.book.emitted += self.emitted_per_step;
        self.book.absorbed += absorbed;
        self.book.escaped += escaped;
        let last = [self.emitted_per_step, absorbed, escaped];
        self.book.rates = if self.steps == 1 {
            last
        } else {
            std::array::from_fn(|i| 0.5 * (self.previous[i] + last[i]))
        };
        self.previous = last;
        let imbalance = self.book.steady_imbalance();
        if size > 0.0 {
            ((change / size).sqrt().max(imbalance), change.sqrt())
        } else if self.shines {
            (1.0, f64::MAX)
        } else {
            (0.0, 0.0)
        }
    }

    /// The books at the end: `held` what the lattice holds, `pending` the escape its walls
    /// have not yet answered.
    pub fn finish(mut self, held: f64, pending: f64) -> Bookkeeping {
        self.book.held = held;
        self.book.escaped += pending;
        self.book
    }
}

/// A marched lattice.
#[derive(Debug, Clone, PartialEq)]
pub struct Marched {
    /// ρ = Σ f_i per cell at the last step (the fluence).
    pub fluence: Vec<f32>,
    /// Steps run.
    pub steps: usize,
    /// Residual after each step.
    pub residuals: Vec<f64>,
    /// Why it stopped.
    pub stop_reason: StopReason,
    /// Energy.
    pub bookkeeping: Bookkeeping,
}

/// The per-cell collision of one operator, with the lattice's constants.
#[derive(Debug, Clone)]
pub(crate) struct Collider {
    pub(crate) links: Links,
    pub(crate) q: usize,
    collision: Collision,
    absorption: Absorption,
    /// Source weights (the equilibrium's: `w` for TRT/BGK, Geist's redistribution for
    /// Geist, whose rest weight is 0).
    source_w: Vec<f32>,
    /// 3 e_i as f32.
    e3: Vec<[f32; 3]>,
    w: Vec<f32>,
    cs2: f32,
    /// Geist's redistribution weight per link (1/6; 1/12 axis, 1/24 diagonal).
    geist_w: Vec<f32>,
    /// Per set of faces a cell touches ([`face_mask`]): the links whose upstream cell
    /// x − e_k is outside the box (they take the wall's inflow), as bits.
    pub(crate) enters: [u32; 64],
    /// Per set of faces: the links that leave the box (x + e_k outside), as bits.
    pub(crate) leaves: [u32; 64],
    /// Per set of faces: the wall's rule as the affine map it is (empty until
    /// [`Collider::with_wall`]).
    rules: Vec<WallRule>,
}

/// The wall's rule on the cells that touch one set of faces: incoming[k̄] = b + Σ_j
/// m_j out[j] over the links j leaving the box, one row per leaving link k (k̄ its
/// opposite). Every rule ([`Wall`]) is affine in the outgoing populations, so the map is
/// found once per set of faces from the generic rule and applied per cell as a few
/// multiply-adds.
#[derive(Debug, Clone, Default)]
struct WallRule {
    /// The links leaving, in order.
    leaving: Vec<usize>,
    /// Per leaving link k: (k̄, b, m over `leaving`).
    rows: Vec<(usize, f32, Vec<f32>)>,
}

/// Which of the box's six faces the cell at `at` touches: bit 2a for the low face of axis
/// a, bit 2a + 1 for the high one (both on an axis one cell wide).
#[inline]
pub(crate) fn face_mask(at: [usize; 3], dims: [usize; 3]) -> usize {
    let mut mask = 0;
    for a in 0..3 {
        if at[a] == 0 {
            mask |= 1 << (2 * a);
        }
        if at[a] + 1 == dims[a] {
            mask |= 1 << (2 * a + 1);
        }
    }
    mask
}

/// Per-cell inputs of a collision.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CellInputs {
    pub(crate) first: f32,
    pub(crate) second: f32,
    pub(crate) source: f32,
    pub(crate) moment: [f32; 3],
}

impl Collider {
    pub(crate) fn new(settings: &MarchSettings) -> Self {
        let links = settings.velocities.links();
        let q = links.e.len();
        let geist_w: Vec<f32> = links
            .e
            .iter()
            .map(|e| {
                let len2 = e.iter().map(|v| v * v).sum::<i32>();
                match (settings.velocities, len2) {
                    (_, 0) => 0.0,
                    (Velocities::D3q7, _) => 1.0 / 6.0,
                    (Velocities::D3q19, 1) => 1.0 / 12.0,
                    (Velocities::D3q19, _) => 1.0 / 24.0,
                }
            })
            .collect();
        let w: Vec<f32> = links.w.iter().map(|&w| w as f32).collect();
        let source_w = match settings.collision {
            Collision::Geist => geist_w.clone(),
            _ => w.clone(),
        };
        let e3 = links.e.iter().map(|e| e.map(|v| 3.0 * v as f32)).collect();
        // Link k crosses face (a, low) if e_ka < 0, (a, high) if e_ka > 0.
        let crosses = |e: [i32; 3], faces: usize| {
            (0..3).any(|a| {
                (e[a] < 0 && faces >> (2 * a) & 1 == 1)
                    || (e[a] > 0 && faces >> (2 * a + 1) & 1 == 1)
            })
        };
        let (mut enters, mut leaves) = ([0u32; 64], [0u32; 64]);
        for faces in 0..64 {
            for (k, e) in links.e.iter().enumerate() {
                if crosses(*e, faces) {
                    leaves[faces] |= 1 << k;
                }
                if crosses(e.map(|v| -v), faces) {
                    enters[faces] |= 1 << k;
                }
            }
        }
        Self {
            cs2: links.cs2 as f32,
            links,
            q,
            collision: settings.collision,
            absorption: settings.absorption,
            source_w,
            e3,
            w,
            geist_w,
            enters,
            leaves,
            rules: Vec::new(),
        }
    }

    /// The collider with `wall`'s rule mapped for every set of faces.
    pub(crate) fn with_wall(settings: &MarchSettings, wall: Wall) -> Self {
        let mut collider = Self::new(settings);
        let q = collider.q;
        collider.rules = (0..64)
            .map(|faces| {
                let leaving: Vec<usize> = (1..q)
                    .filter(|&k| collider.leaves[faces] >> k & 1 == 1)
                    .collect();
                let mut incoming = vec![0.0f32; q];
                let mut out = vec![0.0f32; q];
                collider.wall_rule(wall, faces, &out, &mut incoming);
                let base = incoming.clone();
                let mut columns = Vec::with_capacity(leaving.len());
                for &j in &leaving {
                    out.fill(0.0);
                    out[j] = 1.0;
                    incoming.fill(0.0);
                    collider.wall_rule(wall, faces, &out, &mut incoming);
                    columns.push(incoming.clone());
                }
                let rows = leaving
                    .iter()
                    .map(|&k| {
                        let kbar = collider.links.opposite[k];
                        let b = base[kbar];
                        (
                            kbar,
                            b,
                            columns.iter().map(|column| column[kbar] - b).collect(),
                        )
                    })
                    .collect();
                WallRule { leaving, rows }
            })
            .collect();
        collider
    }

    /// Whether the relaxation collisions (TRT, BGK) run: the lane kernel's operators.
    #[inline]
    pub(crate) fn relaxes(&self) -> bool {
        matches!(self.collision, Collision::Trt | Collision::Bgk)
    }

    /// [`Self::relax_lanes`] for one cell of a Q-link lattice (`f` padded to 19 links).
    fn relax_one<const Q: usize>(
        &self,
        f: &[[f32; 1]; 19],
        [first, second, source]: [&[f32; 1]; 3],
        moment: Option<&[[f32; 1]; 3]>,
        out: &mut [[f32; 1]],
        rho_out: &mut [f32; 1],
        absorbed_out: &mut [f32; 1],
    ) {
        let f: [&[f32; 1]; Q] = std::array::from_fn(|k| &f[k]);
        self.relax_lanes::<1, Q>(
            &f,
            first,
            second,
            source,
            moment,
            out,
            rho_out,
            absorbed_out,
        );
    }

    /// The relaxation collision of L cells at once (populations `f[k][lane]`): the one
    /// definition of its arithmetic, for single cells (L = 1) and for the interior's
    /// blocks of [`LANES`] cells, whose lane loops the compiler vectorises. `moment` is
    /// `None` when the problem has no first moment. Writes `out`, ρ̂ and the absorbed
    /// amount per lane.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(crate) fn relax_lanes<const L: usize, const Q: usize>(
        &self,
        f: &[&[f32; L]; Q],
        d: &[f32; L],
        ka: &[f32; L],
        q0: &[f32; L],
        moment: Option<&[[f32; L]; 3]>,
        out: &mut [[f32; L]],
        rho_out: &mut [f32; L],
        absorbed_out: &mut [f32; L],
    ) {
        let cs2 = self.cs2;
        let mut rho = [0.0f32; L];
        for fk in f {
            for l in 0..L {
                rho[l] += fk[l];
            }
        }
        // The matches are hoisted out of the lane loops, which stay branch-free.
        let (mut even, mut odd) = ([0.0f32; L], [0.0f32; L]);
        let inv_cs2 = 1.0 / cs2;
        for l in 0..L {
            odd[l] = 1.0 / (d[l] * inv_cs2 + 0.5);
        }
        match self.collision {
            Collision::Bgk => even = odd,
            _ => {
                for l in 0..L {
                    even[l] = 1.0 / (0.25 * cs2 / d[l] + 0.5);
                }
            }
        }
        // The fluence at the collision, second order in the source S = Q₀ − κ_a ρ̂:
        // ρ̂ = Σf + S/2 (the populations hold the mean of before and after the source).
        // With the thesis's absorption nothing leaves: S = Q₀, and κ_a ρ̂ moves to the rest.
        let (mut r, mut net, mut kept) = ([0.0f32; L], [0.0f32; L], [0.0f32; L]);
        match self.absorption {
            Absorption::True => {
                for l in 0..L {
                    r[l] = (rho[l] + 0.5 * q0[l]) / (1.0 + 0.5 * ka[l]);
                    absorbed_out[l] = ka[l] * r[l];
                    net[l] = q0[l] - ka[l] * r[l];
                }
            }
            Absorption::Thesis => {
                for l in 0..L {
                    r[l] = rho[l] + 0.5 * q0[l];
                    absorbed_out[l] = 0.0;
                    kept[l] = ka[l] * r[l];
                    net[l] = q0[l] - ka[l] * r[l];
                }
            }
        }
        *rho_out = r;
        // The isotropic source and sink enter the even moments weighted 1 − ω⁺/2; the
        // first moment's odd source is weighted 1 − ω⁻/2, so that it drives the flux
        // 3 c_s² (1/ω⁻ − ½) Q₁ = 3 D Q₁ as P1 has it.
        // The link tables as arrays of the lattice's size: no bounds checks in the loops.
        let w: [f32; Q] = std::array::from_fn(|k| self.w[k]);
        let e3: [[f32; 3]; Q] = std::array::from_fn(|k| self.e3[k]);
        let source_w: [f32; Q] = std::array::from_fn(|k| self.source_w[k]);
        let w0 = w[0];
        for l in 0..L {
            let half = 1.0 - 0.5 * even[l];
            out[0][l] = f[0][l] - even[l] * (f[0][l] - w0 * r[l]) + half * (w0 * net[l] + kept[l]);
        }
        for i in (1..Q).step_by(2) {
            let j = i + 1;
            let wi = w[i];
            for l in 0..L {
                let half = 1.0 - 0.5 * even[l];
                let plus = 0.5 * (f[i][l] + f[j][l]);
                let minus = 0.5 * (f[i][l] - f[j][l]);
                let common = even[l] * (plus - wi * r[l]) - half * wi * net[l];
                out[i][l] = f[i][l] - common - odd[l] * minus;
                out[j][l] = f[j][l] - common + odd[l] * minus;
            }
            if let Some(m) = moment {
                let (ei, ej) = (e3[i], e3[j]);
                let (si, sj) = (source_w[i], source_w[j]);
                for l in 0..L {
                    let odd_half = 1.0 - 0.5 * odd[l];
                    out[i][l] +=
                        odd_half * si * (ei[0] * m[0][l] + ei[1] * m[1][l] + ei[2] * m[2][l]);
                    out[j][l] +=
                        odd_half * sj * (ej[0] * m[0][l] + ej[1] * m[1][l] + ej[2] * m[2][l]);
                }
            }
        }
    }

    /// Collides `f` (incoming populations) into `out`; returns (ρ̂, absorbed). `moment`
    /// says whether the problem has a first moment (the cell's may still be zero).
    #[inline]
    pub(crate) fn collide(
        &self,
        f: &[f32],
        cell: CellInputs,
        moment: bool,
        out: &mut [f32],
    ) -> (f32, f32) {
        let src = |i: usize| {
            let m = cell.moment;
            let e = self.e3[i];
            self.source_w[i] * (cell.source + e[0] * m[0] + e[1] * m[1] + e[2] * m[2])
        };
        match self.collision {
            Collision::Trt | Collision::Bgk => {
                let mut lanes = [[0.0f32; 1]; 19];
                for (l, v) in lanes.iter_mut().zip(f) {
                    l[0] = *v;
                }
                let mut result = [[0.0f32; 1]; 19];
                let m = cell.moment.map(|v| [v]);
                let (mut rho, mut absorbed) = ([0.0f32], [0.0f32]);
                let m = moment.then_some(&m);
                let (first, second, source) = ([cell.first], [cell.second], [cell.source]);
                // One cell through the lane kernel of the lattice's own Q.
                let relax = match self.q {
                    7 => Self::relax_one::<7>,
                    _ => Self::relax_one::<19>,
                };
                relax(
                    self,
                    &lanes,
                    [&first, &second, &source],
                    m,
                    &mut result,
                    &mut rho,
                    &mut absorbed,
                );
                for (o, v) in out.iter_mut().zip(&result) {
                    *o = v[0];
                }
                (rho[0], absorbed[0])
            }
            Collision::Geist => {
                let rho: f32 = f.iter().sum();
                let (kt, ks) = (cell.first, cell.second);
                let ka = kt - ks;
                let moving = rho - f[0];
                let scattered = ks * moving;
                out[0] = match self.absorption {
                    Absorption::Thesis => ka * moving,
                    Absorption::True => 0.0,
                } + src(0);
                for i in 1..self.q {
                    out[i] = self.geist_w[i] * (f[0] + scattered) + (1.0 - kt) * f[i] + src(i);
                }
                let absorbed = match self.absorption {
                    Absorption::True => ka * moving,
                    Absorption::Thesis => 0.0,
                };
                (rho, absorbed)
            }
        }
    }

    /// The wall's incoming populations at a cell touching `faces` ([`face_mask`]) from
    /// its outgoing ones (`out` holds f*_k for the links leaving the box): the rule
    /// [`Collider::with_wall`] mapped, written into `incoming[k̄]`. Returns the net
    /// outflow Σ (f*_k − f_in,k̄).
    #[inline]
    pub(crate) fn wall(&self, faces: usize, out: &[f32], incoming: &mut [f32]) -> f64 {
        let rule = &self.rules[faces];
        let mut escaped = 0.0f64;
        for (&k, (kbar, b, m)) in rule.leaving.iter().zip(&rule.rows) {
            let mut value = *b;
            for (&j, c) in rule.leaving.iter().zip(m) {
                value += c * out[j];
            }
            incoming[*kbar] = value;
            escaped += f64::from(out[k]) - f64::from(value);
        }
        escaped
    }

    /// The wall's incoming populations at a cell from its outgoing ones: for each face the
    /// cell touches, the links leaving through it (`out` holds f*_k for them), ρ_w at the
    /// half-link from the condition, and f_in,k̄ = −f*_k + 2 w_k ρ_w into `incoming[k̄]`
    /// (anti-bounce-back; a link leaving through c faces counts 1/c in each face's sums
    /// and gets the mean of their rules). Returns the net outflow Σ (f*_k − f_in,k̄).
    fn wall_rule(&self, wall: Wall, faces: usize, out: &[f32], incoming: &mut [f32]) -> f64 {
        // How many faces each link leaves through: a link leaving through an edge or a
        // corner counts 1/c in each face's sums and takes the mean of their rules, so
        // that each face's net outflow is its condition's and a reflecting box holds
        // every photon.
        if let Wall::Reflect { reflectance } = wall {
            let r = reflectance as f32;
            let mut escaped = 0.0f64;
            for k in 1..self.q {
                if self.leaves[faces] >> k & 1 == 1 {
                    let value = r * out[k];
                    incoming[self.links.opposite[k]] = value;
                    escaped += f64::from(out[k]) - f64::from(value);
                }
            }
            return escaped;
        }
        let mut crossings = [0u8; 19];
        for axis in 0..3 {
            for side in [-1i32, 1] {
                if on_face(faces, axis, side) {
                    for k in 1..self.q {
                        if self.links.e[k][axis] == side {
                            crossings[k] += 1;
                        }
                    }
                }
            }
        }
        let mut count = [0u8; 19];
        let mut sum = [0f32; 19];
        for axis in 0..3 {
            for side in [-1i32, 1] {
                if !on_face(faces, axis, side) {
                    continue;
                }
                // F = Σ f*_k and W = Σ w_k over the links leaving through this face.
                let (mut big_f, mut big_w) = (0.0f32, 0.0f32);
                for k in 1..self.q {
                    if self.links.e[k][axis] == side {
                        let share = 1.0 / f32::from(crossings[k]);
                        big_f += share * out[k];
                        big_w += share * self.w_wall(k);
                    }
                }
                let rho_w = match wall {
                    Wall::Robin { a } => {
                        let a = a as f32;
                        4.0 * a * big_f / (1.0 + 4.0 * a * big_w)
                    }
                    Wall::Dirichlet { value } => value as f32,
                    Wall::Neumann { flux } => (2.0 * big_f - flux as f32) / (2.0 * big_w),
                    Wall::Reflect { .. } => unreachable!("handled above"),
                };
                for k in 1..self.q {
                    if self.links.e[k][axis] == side {
                        sum[k] += -out[k] + 2.0 * self.w_wall(k) * rho_w;
                        count[k] += 1;
                    }
                }
            }
        }
        let mut escaped = 0.0f64;
        for k in 1..self.q {
            if count[k] > 0 {
                let value = sum[k] / f32::from(count[k]);
                incoming[self.links.opposite[k]] = value;
                escaped += f64::from(out[k]) - f64::from(value);
            }
        }
        escaped
    }

    /// The weight the wall rule uses for link k (the equilibrium's).
    #[inline]
    fn w_wall(&self, k: usize) -> f32 {
        self.source_w[k]
    }
}

/// Checks a problem against the settings before a march (every [`march`] does): sizes,
/// finite sources, coefficients in range and within the stability limits.
pub fn check(problem: &LatticeProblem, settings: &MarchSettings) -> Result<(), LbmError> {
    let n: usize = problem.dims.iter().product();
    if n == 0 {
        return Err(LbmError::Invalid("an empty grid".into()));
    }
    if let Some(b) = settings.blocks {
        if b.slabs == 0 || b.steps_per_visit == 0 {
            return Err(LbmError::Invalid(
                "blockwise scheduling needs at least one slab per block and one step per visit"
                    .into(),
            ));
        }
        if settings.streaming != Streaming::TwoArrays {
            return Err(LbmError::Invalid(
                "blockwise scheduling streams between two arrays of populations".into(),
            ));
        }
    }
    for (name, len) in [
        ("first coefficient", problem.first.len()),
        ("second coefficient", problem.second.len()),
        ("source", problem.source.len()),
    ] {
        if len != n {
            return Err(LbmError::Invalid(format!(
                "{name}: {len} values for {n} cells"
            )));
        }
    }
    if !problem.first_moment.is_empty() && problem.first_moment.len() != n {
        return Err(LbmError::Invalid(
            "first moment: one per cell or none".into(),
        ));
    }
    if let Some(c) = problem
        .source
        .iter()
        .position(|v| !v.is_finite())
        .or_else(|| {
            problem
                .first_moment
                .iter()
                .position(|v| v.iter().any(|x| !x.is_finite()))
        })
    {
        return Err(LbmError::Invalid(format!(
            "a source that is not finite in cell {c}"
        )));
    }
    match settings.collision {
        Collision::Trt | Collision::Bgk => {
            if let Some(c) = problem
                .first
                .iter()
                .position(|d| !(d.is_finite() && *d > 0.0))
            {
                return Err(LbmError::Invalid(format!(
                    "D/h = {} in cell {c}: it must be finite and positive",
                    problem.first[c]
                )));
            }
            // The sink removes κ_a ρ per step; beyond 1 a step removes more than the cell
            // holds and the march oscillates (the stability limit σ_a h < 1).
            if let Some(c) = problem.second.iter().position(|k| !(*k >= 0.0 && *k < 1.0)) {
                return Err(LbmError::Unstable {
                    parameter: "σ_a h",
                    limit: 1.0,
                    value: f64::from(problem.second[c]),
                });
            }
        }
        Collision::Geist => {
            let bad = problem
                .first
                .iter()
                .zip(&problem.second)
                .position(|(t, s)| !(*t >= 0.0 && *t <= 1.0 && *s >= 0.0 && s <= t));
            if let Some(c) = bad {
                return Err(LbmError::Invalid(format!(
                    "per-step probabilities κ_t = {}, κ_s = {} in cell {c}: need 0 ≤ κ_s ≤ κ_t ≤ 1",
                    problem.first[c], problem.second[c]
                )));
            }
        }
    }
    let ok = match problem.wall {
        Wall::Robin { a } => a.is_finite() && a >= 1.0,
        Wall::Dirichlet { value } => value.is_finite(),
        Wall::Neumann { flux } => flux.is_finite(),
        Wall::Reflect { reflectance } => (0.0..=1.0).contains(&reflectance),
    };
    if !ok {
        return Err(LbmError::Invalid(format!(
            "wall condition {:?}",
            problem.wall
        )));
    }
    Ok(())
}

/// Per-slab side storage of the cells on the box's walls (AA pattern): for each such cell
/// and link, the incoming population the wall sends in (`incoming`) and the outgoing one
/// that left through it and awaits the wall's rule (`outgoing`). Keeping them beside the
/// population arrays leaves every population slot to the cells that stream into it.
#[derive(Debug, Clone)]
pub(crate) struct WallSlots {
    /// Per slab: the wall index of each cell (`u32::MAX` for an interior cell).
    index: Vec<Vec<u32>>,
    /// Per slab: Q values per wall cell.
    incoming: Vec<Vec<f32>>,
    outgoing: Vec<Vec<f32>>,
}

impl WallSlots {
    fn new(dims: [usize; 3], q: usize) -> Self {
        let [nx, ny, nz] = dims;
        let mut index = Vec::with_capacity(nz);
        let mut incoming = Vec::with_capacity(nz);
        for z in 0..nz {
            let mut count = 0u32;
            let slab: Vec<u32> = (0..nx * ny)
                .map(|local| {
                    if on_wall([local % nx, local / nx, z], dims) {
                        count += 1;
                        count - 1
                    } else {
                        u32::MAX
                    }
                })
                .collect();
            incoming.push(vec![0.0; count as usize * q]);
            index.push(slab);
        }
        let outgoing = incoming.clone();
        Self {
            index,
            incoming,
            outgoing,
        }
    }
}

/// The state of a march.
pub(crate) struct State {
    /// Populations, one array per link over the cells: AA — post-streaming after odd steps,
    /// post-collision in the opposite slots after even steps; two arrays — post-collision.
    f: Vec<Vec<f32>>,
    /// The second array (two-array streaming).
    g: Vec<Vec<f32>>,
    /// The walls' side slots (AA).
    walls: WallSlots,
    /// ρ at the last step.
    rho: Vec<f32>,
}

/// Per-slab sums of a step.
#[derive(Debug, Clone, Copy)]
struct StepSums {
    change: f64,
    size: f64,
    absorbed: f64,
    escaped: f64,
    /// Escape a step answered ahead of time (the AA odd step's own outgoing populations),
    /// counted with the next step, where the two-array pattern counts it.
    later: f64,
    finite: bool,
}

impl StepSums {
    fn new() -> Self {
        Self {
            change: 0.0,
            size: 0.0,
            absorbed: 0.0,
            escaped: 0.0,
            later: 0.0,
            finite: true,
        }
    }

    fn plus(self, o: Self) -> Self {
        Self {
            change: self.change + o.change,
            size: self.size + o.size,
            absorbed: self.absorbed + o.absorbed,
            escaped: self.escaped + o.escaped,
            later: self.later + o.later,
            finite: self.finite && o.finite,
        }
    }

    /// Adds a block's step (ρ̂ and the absorbed light per lane; `old` holds the last ρ̂
    /// and takes the new): the sums run in four independent f64 accumulators (lanes
    /// l mod 4), so they vectorise and no lane waits on the one before.
    #[inline(always)]
    fn block<const L: usize>(&mut self, rho: &[f32; L], old: &mut [f32], absorbed: &[f32; L]) {
        let (mut change, mut size, mut taken) = ([0.0f64; 4], [0.0f64; 4], [0.0f64; 4]);
        let mut finite = true;
        for l in 0..L {
            let (r, o) = (f64::from(rho[l]), f64::from(old[l]));
            let d = r - o;
            change[l % 4] += d * d;
            size[l % 4] += r * r;
            taken[l % 4] += f64::from(absorbed[l]);
            finite &= rho[l].is_finite();
        }
        store(old, rho);
        let total = |v: [f64; 4]| (v[0] + v[1]) + (v[2] + v[3]);
        self.change += total(change);
        self.size += total(size);
        self.absorbed += total(taken);
        self.finite &= finite;
    }

    /// Adds one cell's step.
    #[inline]
    fn cell(&mut self, rho: f32, old: &mut f32, absorbed: f32) {
        let d = f64::from(rho) - f64::from(*old);
        self.change += d * d;
        self.size += f64::from(rho) * f64::from(rho);
        self.absorbed += f64::from(absorbed);
        self.finite &= rho.is_finite();
        *old = rho;
    }
}

/// Marches `problem` from zero to steady state.
pub fn march(problem: &LatticeProblem, settings: &MarchSettings) -> Result<Marched, LbmError> {
    check(problem, settings)?;
    let collider = Collider::with_wall(settings, problem.wall);
    let [nx, ny, nz] = problem.dims;
    let n = nx * ny * nz;
    let q = collider.q;
    let mut state = State {
        f: vec![vec![0.0; n]; q],
        g: match settings.streaming {
            Streaming::InPlace => Vec::new(),
            Streaming::TwoArrays => vec![vec![0.0; n]; q],
        },
        walls: WallSlots::new(problem.dims, q),
        rho: vec![0.0; n],
    };
    // The zero state's wall answer: the two-array pattern counts it in its first step.
    let mut initial_escape = 0.0f64;
    if settings.streaming == Streaming::InPlace {
        // The zero state's wall inflow (non-zero for a Dirichlet value), as the two-array
        // pattern's first pull computes it.
        let zero = vec![0.0f32; q];
        for (z, slab) in state.walls.index.iter().enumerate() {
            for (local, &w) in slab.iter().enumerate() {
                if w != u32::MAX {
                    let at = [local % nx, local / nx, z];
                    let slot = &mut state.walls.incoming[z][w as usize * q..(w as usize + 1) * q];
                    initial_escape += collider.wall(face_mask(at, problem.dims), &zero, slot);
                }
            }
        }
    }
    let mut ledger = Ledger::new(problem, settings);
    let mut history = History::start();
    let mut carried = initial_escape;
    let stop_reason = loop {
        let mut sums = match settings.streaming {
            Streaming::InPlace if ledger.steps().is_multiple_of(2) => match q {
                7 => aa_even::<7>(problem, &collider, &mut state),
                _ => aa_even::<19>(problem, &collider, &mut state),
            },
            Streaming::InPlace => match q {
                7 => aa_odd::<7>(problem, &collider, &mut state),
                _ => aa_odd::<19>(problem, &collider, &mut state),
            },
            Streaming::TwoArrays => match settings.blocks {
                None => pull(problem, &collider, &mut state),
                Some(blocks) => blockwise(problem, &collider, &mut state, blocks),
            },
        };
        sums.escaped += carried;
        carried = sums.later;
        if !sums.finite {
            ledger.step(sums.absorbed, sums.escaped, sums.change, sums.size);
            break StopReason::DivergedNonFinite {
                iteration: ledger.steps(),
            };
        }
        let (relative, absolute) = ledger.step(sums.absorbed, sums.escaped, sums.change, sums.size);
        if let Some(stop) =
            history.record_step(&settings.stopping, ledger.steps(), relative, absolute)
        {
            break stop;
        }
    };
    let step = ledger.steps();
    let (held, pending) = in_flight(
        problem,
        &collider,
        &state.f,
        Some(&state.walls),
        settings.streaming,
        step,
    );
    Ok(Marched {
        fluence: state.rho,
        steps: step,
        residuals: history.into_residuals(),
        stop_reason,
        bookkeeping: ledger.finish(held, pending + carried),
    })
}

/// Whether `faces` ([`face_mask`]) holds the face of `axis` on `side` (−1 low, +1 high).
#[inline]
fn on_face(faces: usize, axis: usize, side: i32) -> bool {
    faces >> (2 * axis + usize::from(side > 0)) & 1 == 1
}

#[inline]
fn on_wall(at: [usize; 3], dims: [usize; 3]) -> bool {
    (0..3).any(|a| at[a] == 0 || at[a] + 1 == dims[a])
}

#[inline]
fn inputs(problem: &LatticeProblem, c: usize) -> CellInputs {
    CellInputs {
        first: problem.first[c],
        second: problem.second[c],
        source: problem.source[c],
        moment: problem.first_moment.get(c).copied().unwrap_or([0.0; 3]),
    }
}

/// Cells per short block of the interior kernels: the SSE2 lane width the relaxation
/// collision is vectorised over, for the end of a row.
const LANES: usize = 4;

/// Cells per middle block, for the rest of a row after its long blocks: with [`LANES`] and
/// single cells after it, at most three cells of an interior row take the scalar path
/// (with 64 and 8 alone, a 128-cell row left six, 5 % of the cells, each several times
/// the cost of a vectorised one).
const MID: usize = 16;

/// Cells per long block: most of an interior row at once, so that each link's populations
/// move as one contiguous burst per row (a few streams at a time for the prefetchers, not
/// 2Q + 4 interleaved ones) and the per-block work is amortised. 19 × 64 × 4 B × 2 = 9.7 KiB
/// of buffers: L1.
const BIG: usize = 64;

/// A block's collided populations (the inputs are read in place).
struct Buffers<const L: usize> {
    fout: [[f32; L]; 19],
}

impl<const L: usize> Buffers<L> {
    fn new() -> Box<Self> {
        Box::new(Self {
            fout: [[0.0; L]; 19],
        })
    }
}

/// The buffers of every block size a kernel uses.
struct BlockBuffers {
    big: Box<Buffers<BIG>>,
    mid: Box<Buffers<MID>>,
    lanes: Box<Buffers<LANES>>,
    one: Box<Buffers<1>>,
}

impl BlockBuffers {
    fn new() -> Self {
        Self {
            big: Buffers::new(),
            mid: Buffers::new(),
            lanes: Buffers::new(),
            one: Buffers::new(),
        }
    }
}

/// The relaxation collision of the L cells from global index `c`: their inputs read
/// from the problem, `fin` collided into `fout`, the sums accounted in cell order.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn relax_block<const L: usize, const Q: usize>(
    problem: &LatticeProblem,
    collider: &Collider,
    c: usize,
    fin: &[&[f32; L]; Q],
    fout: &mut [[f32; L]; 19],
    rho_slab: &mut [f32],
    local: usize,
    sums: &mut StepSums,
) {
    fn block<const L: usize>(v: &[f32], c: usize) -> &[f32; L] {
        v[c..c + L].try_into().expect("a block")
    }
    let moment = (!problem.first_moment.is_empty()).then(|| {
        let m = &problem.first_moment[c..c + L];
        [0, 1, 2].map(|a| std::array::from_fn(|l| m[l][a]))
    });
    let (mut rho, mut absorbed) = ([0.0f32; L], [0.0f32; L]);
    collider.relax_lanes::<L, Q>(
        fin,
        block(&problem.first, c),
        block(&problem.second, c),
        block(&problem.source, c),
        moment.as_ref(),
        fout,
        &mut rho,
        &mut absorbed,
    );
    sums.block(&rho, &mut rho_slab[local..local + L], &absorbed);
}

/// References to L populations of each of the Q links, `at(k)` giving link k's slice
/// from the block's first cell: the collision reads the arrays in place.
#[inline(always)]
fn lane_refs<'a, const L: usize, const Q: usize>(
    at: impl Fn(usize) -> &'a [f32],
) -> [&'a [f32; L]; Q] {
    std::array::from_fn(|k| at(k)[..L].try_into().expect("a block"))
}

/// Runs `kernel::<L, Q>(args…, buffers of L, sums)` for the block of L cells that `run`
/// ([`interior_run`]) names; nothing for a run of 0 (a wall cell).
macro_rules! by_run {
    ($run:expr, $kernel:ident::<$q:ident>($($arg:expr),* ; $buffers:expr, $sums:expr)) => {
        match $run {
            BIG => $kernel::<BIG, $q>($($arg),*, &mut $buffers.big, $sums),
            MID => $kernel::<MID, $q>($($arg),*, &mut $buffers.mid, $sums),
            LANES => $kernel::<LANES, $q>($($arg),*, &mut $buffers.lanes, $sums),
            1 => $kernel::<1, $q>($($arg),*, &mut $buffers.one, $sums),
            _ => {}
        }
    };
}

/// How many cells from x on a row the interior kernels take at once: a block of [`BIG`],
/// [`MID`] or [`LANES`] where that many interior cells follow, a single cell where fewer do,
/// none on a wall.
#[inline]
fn interior_run(x: usize, y: usize, z: usize, dims: [usize; 3]) -> usize {
    let [nx, ny, nz] = dims;
    if !(z > 0 && z + 1 < nz && y > 0 && y + 1 < ny && x > 0 && x + 1 < nx) {
        0
    } else if x + BIG < nx {
        BIG
    } else if x + MID < nx {
        MID
    } else if x + LANES < nx {
        LANES
    } else {
        1
    }
}

/// Two arrays: L interior cells from global index `c` (slab index `local`) pull
/// f_k(x − e_k), collide, and write their own cells of g.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn pull_block<const L: usize, const Q: usize>(
    problem: &LatticeProblem,
    collider: &Collider,
    f: &[Vec<f32>],
    offsets: &[isize],
    g: &mut [Option<&mut [f32]>],
    (c, local): (usize, usize),
    rho_slab: &mut [f32],
    buffers: &mut Buffers<L>,
    sums: &mut StepSums,
) {
    {
        let fin = lane_refs::<L, Q>(|k| &f[k][(c as isize - offsets[k]) as usize..]);
        relax_block(
            problem,
            collider,
            c,
            &fin,
            &mut buffers.fout,
            rho_slab,
            local,
            sums,
        );
    }
    for k in 0..Q {
        store(
            &mut g[k].as_deref_mut().expect("own chunk")[local..local + L],
            &buffers.fout[k],
        );
    }
}

/// AA even step: L interior cells read their own slots and write f*_k into slot k̄.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn aa_even_block<const L: usize, const Q: usize>(
    problem: &LatticeProblem,
    collider: &Collider,
    f: &mut [Option<&mut [f32]>],
    (c, local): (usize, usize),
    rho_slab: &mut [f32],
    buffers: &mut Buffers<L>,
    sums: &mut StepSums,
) {
    let opposite = &collider.links.opposite;
    {
        let fin = lane_refs::<L, Q>(|k| &f[k].as_deref().expect("own")[local..]);
        relax_block(
            problem,
            collider,
            c,
            &fin,
            &mut buffers.fout,
            rho_slab,
            local,
            sums,
        );
    }
    for k in 0..Q {
        store(
            &mut f[opposite[k]].as_deref_mut().expect("own")[local..local + L],
            &buffers.fout[k],
        );
    }
}

/// AA odd step: L interior cells read slot k̄ of x − e_k and write f*_k into slot k of
/// x + e_k (`offsets`: each link's in-slab offset).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn aa_odd_block<const L: usize, const Q: usize>(
    problem: &LatticeProblem,
    collider: &Collider,
    slots: &mut [Option<&mut [f32]>],
    offsets: &[isize],
    (c, local): (usize, usize),
    rho_slab: &mut [f32],
    buffers: &mut Buffers<L>,
    sums: &mut StepSums,
) {
    let opposite = &collider.links.opposite;
    {
        let fin = lane_refs::<L, Q>(|k| {
            &slots[opposite[k]].as_deref().expect("owned")[(local as isize - offsets[k]) as usize..]
        });
        relax_block(
            problem,
            collider,
            c,
            &fin,
            &mut buffers.fout,
            rho_slab,
            local,
            sums,
        );
    }
    for k in 0..Q {
        let down = (local as isize + offsets[k]) as usize;
        store(
            &mut slots[k].as_deref_mut().expect("owned")[down..down + L],
            &buffers.fout[k],
        );
    }
}

/// Writes a block's collided populations: in pieces of 16 lanes (64 bytes, a cache line),
/// which the compiler moves inline, where one copy of a long block becomes a call to
/// `memmove` per link and block (a tenth of the kernel's time, measured).
#[inline(always)]
fn store<const L: usize>(dst: &mut [f32], src: &[f32; L]) {
    const PIECE: usize = 16;
    if L.is_multiple_of(PIECE) {
        for (d, s) in dst.chunks_exact_mut(PIECE).zip(src.chunks_exact(PIECE)) {
            let d: &mut [f32; PIECE] = d.try_into().expect("a piece");
            let s: &[f32; PIECE] = s.try_into().expect("a piece");
            *d = *s;
        }
    } else {
        dst.copy_from_slice(src);
    }
}

/// Per slab z, of every link's array, chunk z + dz(k) (mutable).
fn chunks_by_slab(
    arrays: &mut [Vec<f32>],
    slab: usize,
    nz: usize,
    dz: impl Fn(usize) -> i32,
) -> Vec<Vec<Option<&mut [f32]>>> {
    let q = arrays.len();
    let mut out: Vec<Vec<Option<&mut [f32]>>> =
        (0..nz).map(|_| (0..q).map(|_| None).collect()).collect();
    for (k, arr) in arrays.iter_mut().enumerate() {
        for (chunk_z, chunk) in arr.chunks_mut(slab).enumerate() {
            let z = chunk_z as i64 - i64::from(dz(k));
            if (0..nz as i64).contains(&z) {
                out[z as usize][k] = Some(chunk);
            }
        }
    }
    out
}

/// Two arrays, pull: f holds post-collision populations; each cell pulls f_k(x − e_k) (the
/// wall's rule on its own outgoing ones where x − e_k is outside), collides into g, and the
/// arrays swap. Reads are shared, writes are the cell's own: one pass, no conflicts.
fn pull(problem: &LatticeProblem, collider: &Collider, state: &mut State) -> StepSums {
    let nz = problem.dims[2];
    let sums = match collider.q {
        7 => pull_slabs::<7>(problem, collider, state, 0..nz),
        _ => pull_slabs::<19>(problem, collider, state, 0..nz),
    };
    std::mem::swap(&mut state.f, &mut state.g);
    sums
}

/// One blockwise sweep: each block of slabs in turn takes its steps, pulling from f (its
/// neighbours' latest populations) into g and copying its slabs of g back into f.
fn blockwise(
    problem: &LatticeProblem,
    collider: &Collider,
    state: &mut State,
    blocks: Blocks,
) -> StepSums {
    let [nx, ny, nz] = problem.dims;
    let slab = nx * ny;
    let mut sums = StepSums::new();
    for start in (0..nz).step_by(blocks.slabs) {
        let range = start..(start + blocks.slabs).min(nz);
        for _ in 0..blocks.steps_per_visit {
            sums = sums.plus(match collider.q {
                7 => pull_slabs::<7>(problem, collider, state, range.clone()),
                _ => pull_slabs::<19>(problem, collider, state, range.clone()),
            });
            let cells = range.start * slab..range.end * slab;
            for (f, g) in state.f.iter_mut().zip(&state.g) {
                f[cells.clone()].copy_from_slice(&g[cells.clone()]);
            }
        }
    }
    sums
}

/// The pull step of the slabs `range`: their cells pull from f and collide into g.
fn pull_slabs<const Q: usize>(
    problem: &LatticeProblem,
    collider: &Collider,
    state: &mut State,
    range: std::ops::Range<usize>,
) -> StepSums {
    let dims = problem.dims;
    let [nx, ny, nz] = dims;
    let q = collider.q;
    let slab = nx * ny;
    let e = &collider.links.e;
    let f = &state.f;
    // Each link's offset in the global numbering: f_k(x − e_k) is at c − offsets[k].
    let offsets: Vec<isize> = e
        .iter()
        .map(|v| v[0] as isize + nx as isize * (v[1] as isize + ny as isize * v[2] as isize))
        .collect();
    let mut g_slabs = chunks_by_slab(&mut state.g, slab, nz, |_| 0);
    g_slabs
        .par_iter_mut()
        .zip(state.rho.par_chunks_mut(slab))
        .enumerate()
        .filter(|(z, _)| range.contains(z))
        .map(|(z, (g, rho_slab))| {
            let mut sums = StepSums::new();
            let (mut fin, mut fout) = (vec![0.0f32; q], vec![0.0f32; q]);
            let (mut outgoing, mut incoming) = (vec![0.0f32; q], vec![0.0f32; q]);
            let mut buffers = BlockBuffers::new();
            for y in 0..ny {
                let mut x = 0;
                while x < nx {
                    let at = [x, y, z];
                    let c = x + nx * y + slab * z;
                    let run = if collider.relaxes() {
                        interior_run(x, y, z, dims)
                    } else {
                        0
                    };
                    let cell = (c, x + nx * y);
                    by_run!(
                        run,
                        pull_block::<Q>(problem, collider, f, &offsets, g, cell, rho_slab;
                            buffers, &mut sums)
                    );
                    if run > 0 {
                        x += run;
                        continue;
                    }
                    let faces = face_mask(at, dims);
                    let (enters, leaves) = (collider.enters[faces], collider.leaves[faces]);
                    if faces != 0 {
                        for k in 0..q {
                            outgoing[k] = if leaves >> k & 1 == 1 { f[k][c] } else { 0.0 };
                        }
                        sums.escaped += collider.wall(faces, &outgoing, &mut incoming);
                    }
                    for k in 0..q {
                        fin[k] = if enters >> k & 1 == 1 {
                            incoming[k]
                        } else {
                            f[k][(c as isize - offsets[k]) as usize]
                        };
                    }
                    let (rho, absorbed) = collider.collide(
                        &fin,
                        inputs(problem, c),
                        !problem.first_moment.is_empty(),
                        &mut fout,
                    );
                    sums.cell(rho, &mut rho_slab[x + nx * y], absorbed);
                    for k in 0..q {
                        g[k].as_deref_mut().expect("own chunk")[x + nx * y] = fout[k];
                    }
                    x += 1;
                }
            }
            sums
        })
        .reduce(StepSums::new, StepSums::plus)
}

/// AA even step: each cell reads its own slots (the walls' inflow from its side slots),
/// collides, writes f*_k into slot k̄ (outgoing through a wall into its side slots).
fn aa_even<const Q: usize>(
    problem: &LatticeProblem,
    collider: &Collider,
    state: &mut State,
) -> StepSums {
    let dims = problem.dims;
    let [nx, ny, nz] = dims;
    let q = collider.q;
    let slab = nx * ny;
    let opposite = &collider.links.opposite;
    let mut slabs = chunks_by_slab(&mut state.f, slab, nz, |_| 0);
    let walls = &mut state.walls;
    slabs
        .par_iter_mut()
        .zip(state.rho.par_chunks_mut(slab))
        .zip(walls.incoming.par_iter_mut())
        .zip(walls.outgoing.par_iter_mut())
        .zip(walls.index.par_iter())
        .enumerate()
        .map(|(z, ((((f, rho_slab), w_in), w_out), index))| {
            let mut sums = StepSums::new();
            let (mut fin, mut fout) = (vec![0.0f32; q], vec![0.0f32; q]);
            let mut buffers = BlockBuffers::new();
            let mut local = 0;
            while local < slab {
                let at = [local % nx, local / nx, z];
                let run = if collider.relaxes() {
                    interior_run(at[0], at[1], z, dims)
                } else {
                    0
                };
                let cell = (local + slab * z, local);
                by_run!(
                    run,
                    aa_even_block::<Q>(problem, collider, f, cell, rho_slab; buffers, &mut sums)
                );
                if run > 0 {
                    local += run;
                    continue;
                }
                let w = index[local];
                for k in 0..q {
                    fin[k] = f[k].as_deref().expect("own")[local];
                }
                let faces = face_mask(at, dims);
                if w != u32::MAX {
                    let side = &w_in[w as usize * q..(w as usize + 1) * q];
                    for k in 0..q {
                        if collider.enters[faces] >> k & 1 == 1 {
                            fin[k] = side[k];
                        }
                    }
                }
                let c = local + slab * z;
                let (rho, absorbed) = collider.collide(
                    &fin,
                    inputs(problem, c),
                    !problem.first_moment.is_empty(),
                    &mut fout,
                );
                sums.cell(rho, &mut rho_slab[local], absorbed);
                for k in 0..q {
                    f[opposite[k]].as_deref_mut().expect("own")[local] = fout[k];
                }
                if w != u32::MAX {
                    let side = &mut w_out[w as usize * q..(w as usize + 1) * q];
                    for k in 0..q {
                        side[k] = if collider.leaves[faces] >> k & 1 == 1 {
                            fout[k]
                        } else {
                            0.0
                        };
                    }
                }
                local += 1;
            }
            sums
        })
        .reduce(StepSums::new, StepSums::plus)
}

/// AA odd step: each cell reads f_k from slot k̄ of x − e_k (the wall's rule on its
/// pending outgoing populations where x − e_k is outside), collides, and writes f*_k into
/// slot k of x + e_k (through a wall: the rule's inflow into its side slots). Slab z owns
/// chunk z + e_kz of link k's array: every slot it reads or writes, and no other slab's.
fn aa_odd<const Q: usize>(
    problem: &LatticeProblem,
    collider: &Collider,
    state: &mut State,
) -> StepSums {
    let dims = problem.dims;
    let [nx, ny, nz] = dims;
    let q = collider.q;
    let slab = nx * ny;
    let e = &collider.links.e;
    let opposite = &collider.links.opposite;
    // Each link's in-slab offset: x − e_k is local − offsets[k] in its chunk.
    let offsets: Vec<isize> = e
        .iter()
        .map(|v| v[0] as isize + nx as isize * v[1] as isize)
        .collect();
    let mut owned = chunks_by_slab(&mut state.f, slab, nz, |k| e[k][2]);
    let walls = &mut state.walls;
    owned
        .par_iter_mut()
        .zip(state.rho.par_chunks_mut(slab))
        .zip(walls.incoming.par_iter_mut())
        .zip(walls.outgoing.par_iter())
        .zip(walls.index.par_iter())
        .enumerate()
        .map(|(z, ((((slots, rho_slab), w_in), w_out), index))| {
            let mut sums = StepSums::new();
            let (mut fin, mut fout) = (vec![0.0f32; q], vec![0.0f32; q]);
            let mut incoming = vec![0.0f32; q];
            let mut buffers = BlockBuffers::new();
            for y in 0..ny {
                let mut x = 0;
                while x < nx {
                    let at = [x, y, z];
                    let local = x + nx * y;
                    let run = if collider.relaxes() {
                        interior_run(x, y, z, dims)
                    } else {
                        0
                    };
                    let cell = (local + slab * z, local);
                    by_run!(
                        run,
                        aa_odd_block::<Q>(problem, collider, slots, &offsets, cell, rho_slab;
                            buffers, &mut sums)
                    );
                    if run > 0 {
                        x += run;
                        continue;
                    }
                    let w = index[local];
                    let faces = face_mask(at, dims);
                    let (enters, leaves) = (collider.enters[faces], collider.leaves[faces]);
                    if w != u32::MAX {
                        let pending = &w_out[w as usize * q..(w as usize + 1) * q];
                        sums.escaped += collider.wall(faces, pending, &mut incoming);
                    }
                    for k in 0..q {
                        fin[k] = if enters >> k & 1 == 1 {
                            incoming[k]
                        } else {
                            // f*_k(x − e_k) sits in slot k̄ of x − e_k = x + e_k̄: chunk
                            // z + e_k̄z of array k̄, this slab's.
                            slots[opposite[k]].as_deref().expect("owned")
                                [(local as isize - offsets[k]) as usize]
                        };
                    }
                    let c = local + slab * z;
                    let (rho, absorbed) = collider.collide(
                        &fin,
                        inputs(problem, c),
                        !problem.first_moment.is_empty(),
                        &mut fout,
                    );
                    sums.cell(rho, &mut rho_slab[local], absorbed);
                    for k in 0..q {
                        if leaves >> k & 1 == 0 {
                            let down = (local as isize + offsets[k]) as usize;
                            slots[k].as_deref_mut().expect("owned")[down] = fout[k];
                        }
                    }
                    if w != u32::MAX {
                        // The outgoing f*_k through the walls: the rule's inflow for the
                        // next (even) step.
                        let side = &mut w_in[w as usize * q..(w as usize + 1) * q];
                        sums.later += collider.wall(faces, &fout, &mut incoming);
                        for k in 0..q {
                            if enters >> k & 1 == 1 {
                                side[k] = incoming[k];
                            }
                        }
                    }
                    x += 1;
                }
            }
            sums
        })
        .reduce(StepSums::new, StepSums::plus)
}

/// What a two-array lattice holds (its post-collision populations `f`, one array per
/// link) and the escape its walls have not yet answered: the end of a [`Ledger`] for a
/// march run elsewhere (the device twin's).
pub fn held_and_pending(
    problem: &LatticeProblem,
    settings: &MarchSettings,
    f: &[Vec<f32>],
) -> (f64, f64) {
    let collider = Collider::with_wall(settings, problem.wall);
    in_flight(problem, &collider, f, None, Streaming::TwoArrays, 0)
}

/// What the lattice holds after `steps` steps (the populations the next step would
/// collide) and the escape still pending (outgoing populations the walls have not yet
/// answered: the rule is applied to them here).
fn in_flight(
    problem: &LatticeProblem,
    collider: &Collider,
    f: &[Vec<f32>],
    walls: Option<&WallSlots>,
    streaming: Streaming,
    steps: usize,
) -> (f64, f64) {
    let dims = problem.dims;
    let [nx, ny, nz] = dims;
    let q = collider.q;
    let e = &collider.links.e;
    let opposite = &collider.links.opposite;
    // f_k(x − e_k) is at c − offsets[k].
    let offsets: Vec<isize> = e
        .iter()
        .map(|v| v[0] as isize + nx as isize * (v[1] as isize + ny as isize * v[2] as isize))
        .collect();
    let after_even = streaming == Streaming::InPlace && steps % 2 == 1;
    let (mut held, mut pending) = (0.0f64, 0.0f64);
    let (mut outgoing, mut incoming) = (vec![0.0f32; q], vec![0.0f32; q]);
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let at = [x, y, z];
                let local = x + nx * y;
                let c = local + nx * ny * z;
                let faces = face_mask(at, dims);
                let (enters, leaves) = (collider.enters[faces], collider.leaves[faces]);
                // The wall's inflow into this cell for the next step. The two-array
                // pattern keeps no side slots: every wall cell is answered from its own
                // outgoing populations.
                if faces != 0 {
                    match streaming {
                        Streaming::InPlace => {
                            let walls = walls.expect("the AA pattern's side slots");
                            let w = walls.index[z][local] as usize;
                            let range = w * q..(w + 1) * q;
                            if after_even {
                                pending +=
                                    collider.wall(faces, &walls.outgoing[z][range], &mut incoming);
                            } else {
                                incoming.copy_from_slice(&walls.incoming[z][range]);
                            }
                        }
                        Streaming::TwoArrays => {
                            for k in 0..q {
                                outgoing[k] = if leaves >> k & 1 == 1 { f[k][c] } else { 0.0 };
                            }
                            pending += collider.wall(faces, &outgoing, &mut incoming);
                        }
                    }
                }
                for k in 0..q {
                    held += f64::from(if enters >> k & 1 == 1 {
                        incoming[k]
                    } else {
                        let uc = (c as isize - offsets[k]) as usize;
                        match streaming {
                            // After an odd step the slots hold post-streaming values.
                            Streaming::InPlace if !after_even => f[k][c],
                            // After an even step f*_k(x − e_k) sits in slot k̄ there.
                            Streaming::InPlace => f[opposite[k]][uc],
                            Streaming::TwoArrays => f[k][uc],
                        }
                    });
                }
            }
        }
    }
    (held, pending)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The mapped wall rules are the generic rule: on every set of faces, every wall and
    /// both lattices, for outgoing populations drawn in [0, 1), the same inflow and
    /// escape to f32 rounding (the map's coefficients are the rule's, rounded once).
    #[test]
    fn mapped_wall_rules_are_the_generic_rule() {
        let walls = [
            Wall::Robin { a: 2.6 },
            Wall::Dirichlet { value: 0.3 },
            Wall::Neumann { flux: -0.01 },
            Wall::Reflect { reflectance: 0.4 },
        ];
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut draw = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        for velocities in [Velocities::D3q7, Velocities::D3q19] {
            for collision in [Collision::Trt, Collision::Geist] {
                for wall in walls {
                    let settings = MarchSettings {
                        velocities,
                        collision,
                        absorption: Absorption::True,
                        streaming: Streaming::InPlace,
                        stopping: lucent_core::Stopping::default(),
                        blocks: None,
                    };
                    let collider = Collider::with_wall(&settings, wall);
                    let q = collider.q;
                    for faces in 0..64 {
                        let out: Vec<f32> = (0..q).map(|_| draw()).collect();
                        let (mut a, mut b) = (vec![0.0f32; q], vec![0.0f32; q]);
                        let mapped = collider.wall(faces, &out, &mut a);
                        let generic = collider.wall_rule(wall, faces, &out, &mut b);
                        for k in 0..q {
                            assert!(
                                (a[k] - b[k]).abs() <= 1e-6 * (1.0 + b[k].abs()),
                                "{velocities:?} {collision:?} {wall:?} faces {faces:06b} link {k}: {} vs {}",
                                a[k],
                                b[k]
                            );
                        }
                        assert!((mapped - generic).abs() <= 1e-5 * (1.0 + generic.abs()));
                    }
                }
            }
        }
    }
}
