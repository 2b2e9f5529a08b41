//! Geometric multigrid on the cut-cell hierarchy, matrix-free, in mixed precision.
//!
//! Levels halve the grid (cells covering 2×2×2 children, rounded up; single-cell axes of a
//! 2D problem stay single) until an axis would drop below 4 cells; the coarsest level is solved by conjugate gradients to 1e-10 in f64.
//! Restriction sums the children's residuals (the equations are integrated over cells, so
//! the sum is the volume-weighted average Mertens asks for), prolongation copies the parent's
//! correction to its children (Mertens' piecewise-constant choice), and coarse operators are
//! rediscretised on the coarsened geometry ([`crate::problem`]).
//!
//! Precision: the solution and the fine residual are f64; each cycle runs in f32 on the
//! correction equation A e = r. Pure f32 stalls near a 1e-6 relative residual; this
//! iterative refinement reaches 1e-10 at the cost of one f64 pass per cycle, which adds
//! the correction to φ, updates the residual by r −= A e and rounds it to f32 for the next
//! cycle (convergence is confirmed on the true residual b − Aφ).
//!
//! Speed: the kernels work on rows of the interior in blocks of contiguous cells, so that
//! the compiler vectorises them; a colour of red–black Gauss–Seidel is computed for every
//! cell of a block and stored on half of them (measured 2× faster than the strided loop).
//! Cells on the box and the rows next to it take the general path.

use crate::region::Region;
use glam::DVec3;
use lucent_core::{StopReason, Stopping};
use std::sync::Mutex;

use rayon::prelude::*;

use crate::error::DiffusionError;
use crate::level::{Level, Origins, norm2};
use crate::problem::{Boundaries, DiffusionProblem, LevelData, coarsen};

/// The shape of a multigrid cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Cycle {
    /// One coarse-grid correction per level.
    #[default]
    V,
    /// Two coarse-grid corrections per level.
    W,
    /// An F-cycle: an F-cycle then a V-cycle on the coarser level.
    F,
    /// A K-cycle (Notay & Vassilevski 2008): on each coarser level, up to two steps of
    /// flexible conjugate gradients preconditioned by the K-cycle below, so the coarse
    /// correction is scaled and combined optimally in the energy norm. Robust where the
    /// coarse operators cannot see jumps of D inside a coarse cell; about the work of a
    /// W-cycle at most. Nonlinear: as a preconditioner it needs flexible CG.
    K,
}

/// The smoother.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Smoother {
    /// Red–black Gauss–Seidel (pre-smoothing red first, post-smoothing black first, so
    /// the cycle is symmetric and can precondition CG).
    #[default]
    RedBlackGaussSeidel,
    /// Weighted Jacobi with damping ω (6/7 is optimal for the 7-point Laplacian).
    Jacobi {
        /// Damping factor in (0, 1].
        omega: f32,
    },
}

/// How to run the multigrid solver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MultigridSettings {
    /// Cycle shape.
    pub cycle: Cycle,
    /// Smoother.
    pub smoother: Smoother,
    /// Sweeps before the coarse-grid correction.
    pub pre_sweeps: usize,
    /// Sweeps after it.
    pub post_sweeps: usize,
    /// Start from full multigrid (nested iteration) instead of zero.
    pub full_multigrid: bool,
    /// How corrections go from coarse to fine.
    pub prolongation: Prolongation,
}

/// Coarse-to-fine interpolation of corrections.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Prolongation {
    /// Copy the parent's value (Mertens' choice): with summed restriction and
    /// rediscretised coarse operators the faster of the two here (0.09 against 0.16 per
    /// V(2,2) cycle on the embedded sphere).
    #[default]
    Constant,
    /// Trilinear interpolation between coarse cell centres, renormalised at boundaries.
    Trilinear,
}

impl Default for MultigridSettings {
    fn default() -> Self {
        Self {
            cycle: Cycle::V,
            smoother: Smoother::RedBlackGaussSeidel,
            pre_sweeps: 2,
            post_sweeps: 2,
            full_multigrid: true,
            prolongation: Prolongation::Constant,
        }
    }
}

/// The history of an iterative solve.
#[derive(Debug, Clone, PartialEq)]
pub struct Convergence {
    /// Relative residual after each iteration (the first entry is before any).
    pub residuals: Vec<f64>,
    /// Why it stopped.
    pub stop_reason: StopReason,
}

impl Convergence {
    /// Iterations run.
    pub fn iterations(&self) -> usize {
        self.residuals.len().saturating_sub(1)
    }

    /// Residual reduction of each iteration.
    pub fn factors(&self) -> Vec<f64> {
        self.residuals.windows(2).map(|w| w[1] / w[0]).collect()
    }

    /// Geometric mean of the reduction factors (the asymptotic rate's estimate).
    pub fn mean_factor(&self) -> f64 {
        let f = self.factors();
        if f.is_empty() {
            return 0.0;
        }
        (f.iter().map(|v| v.max(1e-300).ln()).sum::<f64>() / f.len() as f64).exp()
    }
}

/// One vector per level.
pub(crate) type Work = Vec<Vec<f32>>;

/// Σ aᵢbᵢ in f64 of an f32 vector and a vector of either precision, in a fixed order.
fn dot32<T: Copy + Into<f64> + Sync>(a: &[f32], b: &[T]) -> f64 {
    lucent_core::reduce::dot(a, b)
}

/// One level's operator as the cycles read it, for a device that runs the same cycle
/// (`gpu-diffusion-mg`): the matrix-free form of the `level` module,
/// (A x)_i = (e_i + Σ_f c_f) x_i − Σ_f c_f x_{j(f)}, with each cell storing the coupling
/// through its low face on each axis (0 on the box).
#[derive(Debug, Clone, Copy)]
pub struct LevelOperator<'a> {
    /// Cells per axis (x fastest).
    pub dims: [usize; 3],
    /// Coupling through each cell's low x, y and z face.
    pub couplings: [&'a [f32]; 3],
    /// The diagonal's part that is not a face coupling (absorption, boundary patches).
    pub extra: &'a [f32],
    /// 1/d_i, or 0 outside the medium.
    pub inv_diag: &'a [f32],
}

/// The level hierarchy with its work vectors.
#[derive(Debug)]
pub struct Multigrid {
    pub(crate) levels: Vec<Level>,
    settings: MultigridSettings,
    /// The solves' work vectors, allocated and first touched when the hierarchy is built
    /// and kept between solves (a solve borrows them; a second solve running at the same
    /// time allocates its own): a repeated solve — DSA runs one per transport iteration —
    /// allocates nothing, and the set-up, not the solve, pays the page faults (about 60 MB
    /// at 128³).
    work: Mutex<SolveWork>,
    /// The K-cycle's vectors per level (the first cycle's correction and A times each
    /// correction), allocated by its first visit and kept: empty unless the K-cycle runs.
    krylov: Vec<Mutex<KrylovWork>>,
}

/// What [`Multigrid::krylov_correction`] works in on one level.
#[derive(Debug, Default)]
struct KrylovWork {
    c1: Vec<f32>,
    v1: Vec<f64>,
    v2: Vec<f64>,
}

/// What [`Multigrid::solve`] works in: the cycles' vectors per level and the f64 residual.
#[derive(Debug, Default)]
struct SolveWork {
    levels: Option<(Work, Work, Work)>,
    residual: Vec<f64>,
}

impl Clone for Multigrid {
    /// The same hierarchy; its work vectors are allocated by its first solve.
    fn clone(&self) -> Self {
        Self {
            levels: self.levels.clone(),
            settings: self.settings,
            work: Mutex::default(),
            krylov: self.levels.iter().map(|_| Mutex::default()).collect(),
        }
    }
}

/// The most levels a hierarchy has.
const MAX_LEVELS: usize = 24;

/// Whether a level of `dims` cells has a coarser level: while every axis that has more than
/// one cell has at least four.
fn coarsens(dims: [usize; 3]) -> bool {
    !(dims.iter().any(|&n| n > 1 && n < 4) || dims.iter().all(|&n| n == 1))
}

/// The levels' dimensions and cell sizes of the hierarchy on a fine grid of `dims` cells of
/// size `spacing`, finest first: what [`Multigrid::new`] builds, known without the medium.
pub(crate) fn level_shapes(dims: [usize; 3], spacing: DVec3) -> Vec<([usize; 3], DVec3)> {
    let mut shapes = vec![(dims, spacing)];
    while shapes.len() < MAX_LEVELS && coarsens(shapes[shapes.len() - 1].0) {
        let (d, h) = shapes[shapes.len() - 1];
        shapes.push(crate::problem::coarse_shape(d, h));
    }
    shapes
}

impl Multigrid {
    /// The hierarchy for a fine level.
    pub(crate) fn new(
        fine: LevelData,
        boundaries: &Boundaries,
        settings: MultigridSettings,
    ) -> Self {
        Self::with_depth(fine, boundaries, settings, MAX_LEVELS)
    }

    /// [`Multigrid::new`] with at most `max_levels` levels (the part of a deeper hierarchy
    /// from a coarse level down: the levels a rank cycles alone).
    pub(crate) fn with_depth(
        fine: LevelData,
        boundaries: &Boundaries,
        settings: MultigridSettings,
        max_levels: usize,
    ) -> Self {
        let mut data = vec![fine];
        while data.len() < max_levels && coarsens(data[data.len() - 1].level.dims) {
            let next = coarsen(&data[data.len() - 1], boundaries);
            data.push(next);
        }
        let levels: Vec<Level> = data.into_iter().map(|d| d.level).collect();
        let mut multigrid = Self {
            krylov: levels.iter().map(|_| Mutex::default()).collect(),
            levels,
            settings,
            work: Mutex::default(),
        };
        let (mut b, mut x, mut s) = multigrid.work();
        let mut residual = vec![0.0; multigrid.fine_cells()];
        // Touch every page now (a zeroed allocation is mapped lazily, and a fill with zeros
        // after it may be elided).
        for v in b.iter_mut().chain(&mut x).chain(&mut s) {
            std::hint::black_box(&mut v[..]).fill(0.0);
        }
        std::hint::black_box(&mut residual[..]).fill(0.0);
        multigrid.work = Mutex::new(SolveWork {
            levels: Some((b, x, s)),
            residual,
        });
        multigrid
    }

    /// The hierarchy `solve` builds for `problem`: reusable for many right-hand sides
    /// ([`Multigrid::solve`] with [`DiffusionProblem::rhs`]) and for benchmarks.
    pub fn build(
        problem: &DiffusionProblem,
        settings: MultigridSettings,
    ) -> Result<Self, DiffusionError> {
        crate::solve::check_sweeps(&settings)?;
        Ok(Self::new(
            problem.fine_level(),
            problem.boundaries(),
            settings,
        ))
    }

    /// The levels' operators, finest first.
    pub fn levels(&self) -> Vec<LevelOperator<'_>> {
        self.levels
            .iter()
            .map(|l| LevelOperator {
                dims: l.dims,
                couplings: [&l.couplings[0], &l.couplings[1], &l.couplings[2]],
                extra: &l.extra,
                inv_diag: &l.inv_diag,
            })
            .collect()
    }

    /// The cycle, smoother, sweeps and prolongation the hierarchy runs.
    pub fn settings(&self) -> &MultigridSettings {
        &self.settings
    }

    /// The coarsest level's solve inside a cycle, for `b` on that level: x from zero by
    /// Jacobi-preconditioned CG in f64 to 1e-10.
    pub fn solve_coarsest(&self, b: &[f32]) -> Vec<f32> {
        let mut x = vec![0.0f32; b.len()];
        self.coarsest(b, &mut x);
        x
    }

    /// One cycle of the settings from x = 0 for A x = `b` on the finest level, in f32: the
    /// preconditioner the solves apply, and what a device's cycle must reproduce.
    pub fn cycle_from_zero(&self, b: &[f32]) -> Result<Vec<f32>, DiffusionError> {
        let n = self.fine_cells();
        if b.len() != n {
            return Err(DiffusionError::Invalid(format!(
                "a right-hand side of {} values for {n} cells",
                b.len()
            )));
        }
        let (mut bw, mut x, mut s) = self.work();
        bw[0].copy_from_slice(b);
        self.cycle(0, self.settings.cycle, &mut bw, &mut x, &mut s);
        Ok(std::mem::take(&mut x[0]))
    }

    /// Cells of the finest level (the length of its vectors).
    pub fn fine_cells(&self) -> usize {
        self.fine().len()
    }

    /// Cells of the finest level that the sweeps visit: each row's span between its first
    /// and last cell in the medium (cells outside it are not unknowns).
    pub fn swept_cells(&self) -> usize {
        self.fine().swept_cells()
    }

    /// Bytes one smoothing sweep must move at the least: per cell, three face couplings,
    /// the diagonal's extra part, the inverse diagonal and b read once (4 bytes each) and x
    /// read and written once. Cache misses on neighbours come on top.
    pub const SWEEP_BYTES_PER_CELL: u64 = 32;

    /// One red–black Gauss–Seidel sweep on the finest level for A x = b in f32, the kernel
    /// the cycles spend their time in (what `cargo xtask bench-diffusion` times).
    pub fn smoothing_sweep(&self, b: &[f32], x: &mut [f32]) -> Result<(), DiffusionError> {
        let n = self.fine_cells();
        if b.len() != n || x.len() != n {
            return Err(DiffusionError::Invalid(format!(
                "sweep vectors of {} and {} values for {n} cells",
                b.len(),
                x.len()
            )));
        }
        self.fine().gauss_seidel(b, x, 0);
        Ok(())
    }

    /// The finest level.
    pub(crate) fn fine(&self) -> &Level {
        &self.levels[0]
    }

    /// Number of levels.
    pub fn depth(&self) -> usize {
        self.levels.len()
    }

    /// Bytes of the operator and work vectors over all levels.
    pub fn memory_bytes(&self) -> u64 {
        self.levels.iter().map(|l| l.len() as u64 * 4 * 8).sum()
    }

    pub(crate) fn work(&self) -> (Work, Work, Work) {
        let b = self.levels.iter().map(|l| vec![0.0f32; l.len()]).collect();
        let x = self.levels.iter().map(|l| vec![0.0f32; l.len()]).collect();
        let s = self
            .levels
            .iter()
            .map(|l| match self.settings.smoother {
                Smoother::Jacobi { .. } => vec![0.0f32; l.len()],
                Smoother::RedBlackGaussSeidel => Vec::new(),
            })
            .collect();
        (b, x, s)
    }

    fn smooth(&self, l: usize, b: &[f32], x: &mut [f32], scratch: &mut [f32], post: bool) {
        let level = &self.levels[l];
        let sweeps = if post {
            self.settings.post_sweeps
        } else {
            self.settings.pre_sweeps
        };
        for _ in 0..sweeps {
            match self.settings.smoother {
                Smoother::RedBlackGaussSeidel => {
                    level.gauss_seidel(b, x, usize::from(post));
                }
                Smoother::Jacobi { omega } => level.jacobi(b, x, omega, scratch),
            }
        }
    }

    /// Solves the coarsest level by Jacobi-preconditioned CG in f64.
    pub(crate) fn coarsest(&self, b: &[f32], x: &mut [f32]) {
        let level = &self.levels[self.levels.len() - 1];
        let b64: Vec<f64> = b.iter().map(|&v| f64::from(v)).collect();
        let mut x64: Vec<f64> = x.iter().map(|&v| f64::from(v)).collect();
        let stopping = Stopping {
            relative_tolerance: 1e-10,
            max_iterations: 10 * level.len().max(50),
            ..Stopping::default()
        };
        let _ = crate::krylov::conjugate_gradient(level, &b64, &mut x64, &stopping, |r, z| {
            z.iter_mut()
                .zip(r)
                .zip(&level.inv_diag)
                .for_each(|((z, r), d)| *z = r * f64::from(*d));
        });
        for (x, v) in x.iter_mut().zip(x64) {
            *x = v as f32;
        }
    }

    /// One cycle on level `l` for A x = b (x holds the initial guess).
    pub(crate) fn cycle(
        &self,
        l: usize,
        cycle: Cycle,
        b: &mut [Vec<f32>],
        x: &mut [Vec<f32>],
        s: &mut [Vec<f32>],
    ) {
        if l + 1 == self.levels.len() {
            self.coarsest(&b[l], &mut x[l]);
            return;
        }
        {
            let (bl, xl, sl) = (&b[l], &mut x[l], &mut s[l]);
            self.smooth(l, bl, xl, sl, false);
        }
        {
            let (bf, bc) = b.split_at_mut(l + 1);
            let coarse = &self.levels[l + 1];
            self.levels[l].restrict_residual(
                &bf[l],
                &x[l],
                coarse,
                &mut bc[0],
                &coarse.whole(),
                Origins::default(),
            );
        }
        x[l + 1].fill(0.0);
        match cycle {
            Cycle::V => self.cycle(l + 1, Cycle::V, b, x, s),
            Cycle::W => {
                self.cycle(l + 1, Cycle::W, b, x, s);
                self.cycle(l + 1, Cycle::W, b, x, s);
            }
            Cycle::F => {
                self.cycle(l + 1, Cycle::F, b, x, s);
                self.cycle(l + 1, Cycle::V, b, x, s);
            }
            Cycle::K => self.krylov_correction(l + 1, b, x, s),
        }
        {
            let (xf, xc) = x.split_at_mut(l + 1);
            self.prolong(l, &xc[0], &mut xf[l], &self.levels[l].whole());
        }
        let (bl, xl, sl) = (&b[l], &mut x[l], &mut s[l]);
        self.smooth(l, bl, xl, sl, true);
    }

    /// The K-cycle's coarse correction on level `m` for A e = b[m]: one K-cycle gives c₁,
    /// the step α₁/ρ₁ along it minimises the energy error (ρ₁ = c₁ᵀA c₁, α₁ = c₁ᵀb); if the
    /// residual left is above a quarter of b's, a second K-cycle on it gives c₂, which is
    /// A-orthogonalised against c₁ and stepped along likewise (flexible CG, two steps).
    /// Dot products in f64; leaves e in x[m] (b[m] is overwritten).
    pub(crate) fn krylov_correction(
        &self,
        m: usize,
        b: &mut [Vec<f32>],
        x: &mut [Vec<f32>],
        s: &mut [Vec<f32>],
    ) {
        const THRESHOLD: f64 = 0.25;
        x[m].fill(0.0);
        self.cycle(m, Cycle::K, b, x, s);
        if m + 1 == self.levels.len() {
            // The coarsest level's solve is exact: nothing to accelerate.
            return;
        }
        let level = &self.levels[m];
        // The level's kept vectors (a solve running beside this one on the same
        // hierarchy works in its own).
        let mut own = KrylovWork::default();
        let mut kept = self.krylov[m].try_lock();
        let KrylovWork { c1, v1, v2 } = match kept.as_deref_mut() {
            Ok(work) => work,
            Err(_) => &mut own,
        };
        c1.clear();
        c1.extend_from_slice(&x[m]);
        v1.resize(c1.len(), 0.0);
        level.apply(c1, v1);
        let rho1 = dot32(c1, v1);
        let alpha1 = dot32(c1, &b[m]);
        if !(rho1 > 0.0 && rho1.is_finite()) {
            return;
        }
        let step1 = alpha1 / rho1;
        let b_norm = norm2(&b[m]);
        // r̃ = b − (α₁/ρ₁) A c₁ replaces b[m] for the second cycle.
        let left = b[m]
            .par_iter_mut()
            .zip(v1.par_iter())
            .map(|(b, v)| {
                let r = f64::from(*b) - step1 * v;
                *b = r as f32;
                r * r
            })
            .sum::<f64>()
            .sqrt();
        if left <= THRESHOLD * b_norm {
            x[m].par_iter_mut()
                .zip(c1.par_iter())
                .for_each(|(x, c)| *x = (step1 * f64::from(*c)) as f32);
            return;
        }
        x[m].fill(0.0);
        self.cycle(m, Cycle::K, b, x, s);
        let c2 = &x[m];
        v2.resize(c2.len(), 0.0);
        level.apply(c2, v2);
        let gamma = dot32(c2, v1);
        let beta = dot32(c2, v2);
        let alpha2 = dot32(c2, &b[m]);
        let rho2 = beta - gamma * gamma / rho1;
        if !(rho2 > 0.0 && rho2.is_finite()) {
            x[m].par_iter_mut()
                .zip(c1.par_iter())
                .for_each(|(x, c)| *x = (step1 * f64::from(*c)) as f32);
            return;
        }
        let w1 = step1 - gamma * alpha2 / (rho1 * rho2);
        let w2 = alpha2 / rho2;
        x[m].par_iter_mut()
            .zip(c1.par_iter())
            .for_each(|(x, c)| *x = (w1 * f64::from(*c) + w2 * f64::from(*x)) as f32);
    }

    /// Adds the prolonged correction to `region` of level `l`.
    pub(crate) fn prolong(&self, l: usize, coarse: &[f32], fine: &mut [f32], region: &Region) {
        match self.settings.prolongation {
            Prolongation::Constant => self.levels[l].prolong_add(
                &self.levels[l + 1],
                coarse,
                fine,
                region,
                Origins::default(),
            ),
            Prolongation::Trilinear => self.levels[l].prolong_trilinear_add(
                &self.levels[l + 1],
                coarse,
                fine,
                region,
                Origins::default(),
            ),
        }
    }

    /// Work vectors for [`Multigrid::precondition`], allocated once per solve.
    pub(crate) fn preconditioner_work(&self) -> (Work, Work, Work) {
        self.work()
    }

    /// Applies one cycle from zero to `r`: z ≈ A⁻¹ r (the preconditioner of CG).
    pub(crate) fn precondition(&self, work: &mut (Work, Work, Work), r: &[f64], z: &mut [f64]) {
        let (b, x, s) = work;
        b[0].par_iter_mut()
            .zip(r.par_iter())
            .for_each(|(b, r)| *b = *r as f32);
        x[0].fill(0.0);
        self.cycle(0, self.settings.cycle, b, x, s);
        z.par_iter_mut()
            .zip(x[0].par_iter())
            .for_each(|(z, x)| *z = f64::from(*x));
    }

    /// Full multigrid: sums the right-hand side down every level, solves the coarsest, then
    /// on each finer level starts from the prolonged coarse solution and runs one cycle.
    fn full_multigrid(
        &self,
        rhs: &[f64],
        b: &mut [Vec<f32>],
        x: &mut [Vec<f32>],
        s: &mut [Vec<f32>],
    ) {
        b[0].par_iter_mut()
            .zip(rhs.par_iter())
            .for_each(|(b, r)| *b = *r as f32);
        for l in 0..self.levels.len() - 1 {
            let (bf, bc) = b.split_at_mut(l + 1);
            let coarse = &self.levels[l + 1];
            self.levels[l].restrict(
                &bf[l],
                coarse,
                &mut bc[0],
                &coarse.whole(),
                Origins::default(),
            );
        }
        let last = self.levels.len() - 1;
        x[last].fill(0.0);
        self.coarsest(&b[last], &mut x[last]);
        for l in (0..last).rev() {
            x[l].fill(0.0);
            {
                let (xf, xc) = x.split_at_mut(l + 1);
                self.prolong(l, &xc[0], &mut xf[l], &self.levels[l].whole());
            }
            self.cycle(l, self.settings.cycle, b, x, s);
        }
    }

    /// Solves A φ = b to the stopping rule: f64 solution and residual, f32 cycles on the
    /// correction. `phi` holds the initial guess (ignored when full multigrid is on).
    ///
    /// # Panics
    /// If `rhs` or `phi` is not [`Multigrid::fine_cells`] long: the hierarchy is built for
    /// one problem, whose [`DiffusionProblem::rhs`] has that length (the registry's solvers
    /// and `DeviceMultigrid::solve` check lengths and return typed errors).
    pub fn solve(&self, rhs: &[f64], phi: &mut [f64], stopping: &Stopping) -> Convergence {
        let cycle = self.settings.cycle;
        let solved = self.iterate(rhs, phi, stopping, true, |(b, x, s)| {
            x[0].fill(0.0);
            self.cycle(0, cycle, b, x, s);
            Ok::<(), std::convert::Infallible>(())
        });
        match solved {
            Ok(convergence) => convergence,
            Err(never) => match never {},
        }
    }

    /// [`Multigrid::solve`] with each cycle run by `cycle`, which maps the fine level's
    /// right-hand side (the f32 residual) to the correction from zero — a device's cycle
    /// ([`Multigrid::cycle_from_zero`] on the host). The f64 solution, residual and
    /// stopping rule stay here; full multigrid is not run (it would run on the host), so
    /// `phi` is the initial guess. An error of `cycle` stops the solve and is returned.
    ///
    /// # Panics
    /// As [`Multigrid::solve`], on vectors of the wrong length.
    pub fn solve_with<E>(
        &self,
        rhs: &[f64],
        phi: &mut [f64],
        stopping: &Stopping,
        mut cycle: impl FnMut(&[f32]) -> Result<Vec<f32>, E>,
    ) -> Result<Convergence, E> {
        self.iterate(rhs, phi, stopping, false, |(b, x, _)| {
            x[0] = cycle(&b[0])?;
            Ok(())
        })
    }

    /// The outer iteration of the solves: `cycle` reads the fine right-hand side from
    /// `b[0]` and leaves the correction in `x[0]`.
    fn iterate<E>(
        &self,
        rhs: &[f64],
        phi: &mut [f64],
        stopping: &Stopping,
        full_multigrid: bool,
        cycle: impl FnMut((&mut Work, &mut Work, &mut Work)) -> Result<(), E>,
    ) -> Result<Convergence, E> {
        let n = self.fine_cells();
        assert!(
            rhs.len() == n && phi.len() == n,
            "Multigrid::solve: a right-hand side of {} and a solution of {} values for a hierarchy of {n} cells",
            rhs.len(),
            phi.len()
        );
        let started = std::time::Instant::now();
        let mut work = self
            .work
            .try_lock()
            .map(|mut w| std::mem::take(&mut *w))
            .unwrap_or_default();
        let (mut b, mut x, mut s) = work.levels.take().unwrap_or_else(|| self.work());
        let mut r = std::mem::take(&mut work.residual);
        r.resize(rhs.len(), 0.0);
        let result = self.iterate_in(
            rhs,
            phi,
            stopping,
            full_multigrid,
            (&mut b, &mut x, &mut s, &mut r),
            started,
            cycle,
        );
        if let Ok(mut w) = self.work.try_lock() {
            *w = SolveWork {
                levels: Some((b, x, s)),
                residual: r,
            };
        }
        result
    }

    /// [`Multigrid::iterate`] in the given work vectors.
    #[allow(clippy::type_complexity, clippy::too_many_arguments)]
    fn iterate_in<E>(
        &self,
        rhs: &[f64],
        phi: &mut [f64],
        stopping: &Stopping,
        full_multigrid: bool,
        (b, x, s, r): (&mut Work, &mut Work, &mut Work, &mut Vec<f64>),
        started: std::time::Instant,
        mut cycle: impl FnMut((&mut Work, &mut Work, &mut Work)) -> Result<(), E>,
    ) -> Result<Convergence, E> {
        let fine = self.fine();
        if full_multigrid && self.settings.full_multigrid {
            self.full_multigrid(rhs, b, x, s);
            phi.par_iter_mut()
                .zip(x[0].par_iter())
                .for_each(|(p, x)| *p = f64::from(*x));
        }
        // Each cycle's correction updates φ and its residual in one pass (r −= A e); the
        // updated residual drifts from b − Aφ only by rounding, and convergence is
        // confirmed on the true one.
        // Norms sum runs of eight cells along x exactly (`Level::norm`): the same bits on
        // any number of threads or ranks (`Multigrid::solve_on_ranks`).
        let b_norm = fine.norm(rhs).max(f64::MIN_POSITIVE);
        let mut norm = fine.residual(rhs, phi, r);
        b[0].par_iter_mut()
            .zip(r.par_iter())
            .for_each(|(b, r)| *b = *r as f32);
        let mut residuals = vec![norm / b_norm];
        let initial = residuals[0];
        loop {
            let iteration = residuals.len() - 1;
            if let Some(reason) = stopping.verdict(iteration, norm / b_norm, norm, initial, started)
            {
                if !reason.is_converged() {
                    return Ok(Convergence {
                        residuals,
                        stop_reason: reason,
                    });
                }
                norm = fine.residual(rhs, phi, r);
                *residuals.last_mut().unwrap_or(&mut 0.0) = norm / b_norm;
                if let Some(stop_reason) = stopping
                    .verdict(iteration, norm / b_norm, norm, initial, started)
                    .filter(|r| r.is_converged())
                {
                    return Ok(Convergence {
                        residuals,
                        stop_reason,
                    });
                }
                b[0].par_iter_mut()
                    .zip(r.par_iter())
                    .for_each(|(b, r)| *b = *r as f32);
            }
            cycle((b, x, s))?;
            norm = fine.correct(&x[0], phi, r, &mut b[0]);
            residuals.push(norm / b_norm);
        }
    }
}
