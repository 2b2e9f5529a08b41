//! The multigrid on ranks from each rank's part of the medium alone: no rank assembles
//! the whole problem, builds the whole hierarchy or holds the whole right-hand side or φ.
//!
//! For a medium that fills the grid's box ([`SlabSystem`]), every level's operator is
//! local: a fine cell's couplings need D of the cell and the neighbour below it, and a
//! coarse cell's couplings, absorption and patches are sums over its eight children
//! (`problem::coarsen_in`), which a stage's boxes keep on one rank. So each rank builds
//! its own frames level by level:
//! 1. the fine level's couplings, absorption and patches of its box from its fields (the
//!    box and the cell beyond each face, read by positioned reads);
//! 2. on each split level, the couplings of the cells around its box from its neighbours
//!    (faces, edges and corners), then the diagonal of its box (`finish_level`), then the
//!    diagonal of the cells around it likewise: the frame is then, bit for bit, the frame
//!    a rank extracts from the whole hierarchy;
//! 3. within a stage, the next level of its box by coarsening its own cells; where the
//!    next level starts a stage, the coarse cells its box restricts to, handed to their
//!    owners in the next stage as the right-hand side is (couplings, absorption, and the
//!    boundary patches as eleven numbers each), and the owners' operator handed back onto
//!    the hand-over frames as the correction is;
//! 4. rank 0 builds its serial levels as a hierarchy of their own from the first of them.
//!
//! Each step sums what the whole build sums in the same order, so the frames, the history
//! and φ are the bits of [`Multigrid::solve`] on the assembled problem (test:
//! `crates/diffusion/tests/it/ranks.rs`).

use std::borrow::Cow;
use std::ops::Range;

use glam::DVec3;
use lucent_core::Stopping;
use lucent_core::ranks::{Communicator, all_reduce};

use super::{
    Decomposition, Frame, Held, OnRanks, RankLayout, Serial, check_layout, frames, protocol,
};
use crate::error::DiffusionError;
use crate::geometry::Side;
use crate::level::Level;
use crate::multigrid::{Convergence, Multigrid, MultigridSettings, level_shapes};
use crate::problem::{Boundaries, LevelData, LevelParts, LevelPatch, coarsen_in};
use crate::region::Region;
use crate::slab::{BlockFields, PointShares, SlabSystem};

/// One rank's part of a solve on ranks from its part of the medium
/// ([`SlabSystem::solve_multigrid_on_layout`]).
#[derive(Debug, Clone, PartialEq)]
pub struct BoxSolution {
    /// The rank's cells of the fine level (empty on a rank the fine level leaves out).
    pub cells: [Range<usize>; 3],
    /// φ on them (W/cm²), x fastest, then y, then z.
    pub fluence: Vec<f64>,
    /// The residual history and why the solve stopped: the same on every rank.
    pub convergence: Convergence,
}

/// A boundary patch as eleven numbers (its cell's coordinates in the level, area,
/// distance, normal, D, side, width), for the hand-over of a coarse level's operator.
const PATCH_WORDS: usize = 11;

fn side_code(side: Side) -> f64 {
    match side {
        Side::Surface => -1.0,
        Side::Box(face) => face as f64,
    }
}

fn side_of(code: f64) -> Option<Side> {
    if code == -1.0 {
        Some(Side::Surface)
    } else if (0.0..6.0).contains(&code) && code.fract() == 0.0 {
        Some(Side::Box(code as usize))
    } else {
        None
    }
}

/// Cell `index` of `frame` (of a level of `dims` cells) as cell coordinates of the level.
fn level_cell(frame: &Frame, index: usize) -> [usize; 3] {
    let [fx, fy, _] = frame.dims;
    let local = [index % fx, (index / fx) % fy, index / (fx * fy)];
    std::array::from_fn(|a| local[a] + frame.origin[a])
}

/// Cell `at` of a level in `frame`'s indices (it must lie inside).
fn frame_index(frame: &Frame, at: [usize; 3]) -> usize {
    let [fx, fy, _] = frame.dims;
    let l: [usize; 3] = std::array::from_fn(|a| at[a] - frame.origin[a]);
    l[0] + fx * (l[1] + fy * l[2])
}

fn contains(region: &Region, at: [usize; 3]) -> bool {
    (0..3).all(|a| region.axes[a].contains(&at[a]))
}

impl SlabSystem {
    /// How [`SlabSystem::solve_multigrid_on_layout`] splits the multigrid of this grid
    /// over `ranks` ranks (as [`Multigrid::layout`] splits the hierarchy `Multigrid::build`
    /// makes for the same grid): each rank reads the fields of `layout.owned(rank, 0)`
    /// and the cell beyond each of its faces.
    ///
    /// # Errors
    /// As [`Multigrid::layout`].
    pub fn multigrid_layout(
        &self,
        settings: &MultigridSettings,
        ranks: usize,
        coarse_cells_per_rank: usize,
        decomposition: Decomposition,
    ) -> Result<RankLayout, DiffusionError> {
        let g = self.geometry();
        let dims: Vec<[usize; 3]> = level_shapes(g.dims(), g.spacing())
            .into_iter()
            .map(|(d, _)| d)
            .collect();
        RankLayout::with(
            &dims,
            ranks,
            settings.cycle,
            coarse_cells_per_rank,
            decomposition,
        )
    }

    /// The multigrid solve of this box problem on the ranks of `comm`, each rank building
    /// its part of the hierarchy from its own part of the medium: `fields` covers the
    /// rank's fine box (`layout.owned(rank, 0)`) and, for D, the cell beyond each of its
    /// faces that the grid has ([`SlabSystem::block`]'s fields; none on a rank the fine
    /// level leaves out). Every rank passes the same `points`, `settings`, `stopping` and
    /// `layout` ([`SlabSystem::multigrid_layout`]). The solve starts from zero (or full
    /// multigrid); each rank gets back φ on its box, and the history and stop reason that
    /// [`Multigrid::solve`] gives for the assembled problem, bit for bit.
    ///
    /// # Errors
    /// [`DiffusionError::Invalid`] for fields a rank refuses (every rank returns an error:
    /// the others name the failure as [`DiffusionError::Ranks`]), bad settings or a layout
    /// of another grid; [`DiffusionError::Ranks`] if a rank left the protocol.
    pub fn solve_multigrid_on_layout(
        &self,
        fields: BlockFields<'_>,
        points: &[PointShares],
        settings: MultigridSettings,
        stopping: &Stopping,
        comm: &(impl Communicator + ?Sized),
        layout: RankLayout,
    ) -> Result<BoxSolution, DiffusionError> {
        let g = self.geometry();
        let shapes = level_shapes(g.dims(), g.spacing());
        let dims: Vec<[usize; 3]> = shapes.iter().map(|&(d, _)| d).collect();
        crate::solve::check_sweeps(&settings)?;
        check_layout(&layout, &dims, settings.cycle, comm.size())?;
        let rank = comm.rank();
        let owned = layout.owned(rank, 0);
        let cells = owned.axes.clone();
        // The rank's fields and right-hand side, checked; every rank learns whether any
        // rank refused its fields before any of them builds.
        let rhs = if owned.is_empty() {
            Ok(Vec::new())
        } else {
            self.block_rhs(&cells, &fields, points)
        };
        // 1 + the rank that failed (the highest, when several did), or 0.
        let failed = if rhs.is_err() { rank as f64 + 1.0 } else { 0.0 };
        let any_failed = all_reduce(comm, &[failed], |acc, part| {
            acc[0] = acc[0].max(part[0]);
            part.len() == 1
        })
        .ok_or_else(|| protocol(rank, "the fields' check"))?;
        let rhs = rhs?;
        if any_failed[0] != 0.0 {
            return Err(DiffusionError::Ranks(format!(
                "rank {rank}: rank {} refused its part of the medium (it says why)",
                any_failed[0] - 1.0
            )));
        }
        let on = OnRanks::build(self, &fields, &shapes, settings, comm, layout)?;
        // rhs and φ on the fine frame: the box's values, zero around it.
        let frame = on.held[0].as_ref().map_or(
            Frame {
                origin: [0; 3],
                dims: [0; 3],
            },
            |h| h.frame.clone(),
        );
        let box_in_frame = frame.local(&owned);
        let mut rhs_held = vec![0.0f64; frame.len()];
        if !owned.is_empty() && !box_in_frame.write(frame.dims, &mut rhs_held, &rhs, |v| v) {
            return Err(protocol(rank, "the right-hand side's box"));
        }
        let mut phi_held = vec![0.0f64; frame.len()];
        let convergence = on.iterate(&rhs_held, &mut phi_held, stopping)?;
        let fluence = if owned.is_empty() {
            Vec::new()
        } else {
            box_in_frame.read(frame.dims, &phi_held, |v| v)
        };
        Ok(BoxSolution {
            cells,
            fluence,
            convergence,
        })
    }
}

impl<'a, C: Communicator + ?Sized> OnRanks<'a, C> {
    /// The rank's frames of the hierarchy of levels `shapes` built from its `fields`
    /// alone (the module's steps 1–4).
    fn build(
        system: &SlabSystem,
        fields: &BlockFields<'_>,
        shapes: &[([usize; 3], DVec3)],
        settings: MultigridSettings,
        comm: &'a C,
        layout: RankLayout,
    ) -> Result<Self, DiffusionError> {
        let rank = comm.rank();
        let dims: Vec<[usize; 3]> = shapes.iter().map(|&(d, _)| d).collect();
        let depth = dims.len();
        let boundaries = *system.boundaries();
        let (held, handover) = frames(&layout, &dims, rank);
        // Empty operators until each level is built.
        let placeholder = |frame: Frame| Held {
            frame,
            level: Cow::Owned(Level::new(
                [0; 3],
                DVec3::ONE,
                [Vec::new(), Vec::new(), Vec::new()],
                Vec::new(),
                Vec::new(),
                Vec::new(),
            )),
        };
        let mut on = Self {
            settings,
            dims,
            serial: None,
            comm,
            layout,
            rank,
            held: held.into_iter().map(|f| f.map(placeholder)).collect(),
            handover: handover.into_iter().map(|f| f.map(placeholder)).collect(),
        };
        let serial_first = on.layout.stages.last().map_or(0, |s| s.first_level);
        // The fine level's parts on this rank's frame.
        let mut parts: Option<LevelParts> = on.held[0]
            .as_ref()
            .map(|h| system.frame_parts(&on.owned(0).axes, fields, h.frame.origin, h.frame.dims));
        for l in 0..depth {
            let starts = l > 0 && on.stage(l).first_level == l;
            if l == serial_first {
                // Rank 0 holds the whole level: the rest of the hierarchy is its own.
                let whole = match parts.take() {
                    Some(p) if rank == 0 => Some(p.finish(&boundaries)),
                    None if rank != 0 => None,
                    _ => return Err(protocol(rank, "the serial levels' operator")),
                };
                let mg = whole.map(|data| {
                    Multigrid::with_depth(data, &boundaries, settings, depth - serial_first)
                });
                if mg.as_ref().is_some_and(|mg| mg.levels.len() != depth - l) {
                    return Err(protocol(rank, "the serial levels' depth"));
                }
                if starts {
                    let up =
                        on.hand_up_operator(l, mg.as_ref().map(|mg| &mg.levels[0]), shapes[l].1)?;
                    on.set_handover(l, up);
                }
                on.serial = mg.map(|mg| Serial {
                    first: serial_first,
                    mg: Cow::Owned(mg),
                });
                break;
            }
            let rest = match on.finish_split(l, parts.take(), &boundaries)? {
                Some((level, rest)) => {
                    if let Some(h) = on.held[l].as_mut() {
                        h.level = Cow::Owned(level);
                    }
                    Some(rest)
                }
                None => None,
            };
            if starts {
                let level = on.held[l].as_ref().map(|h| &*h.level);
                let up = on.hand_up_operator(l, level, shapes[l].1)?;
                on.set_handover(l, up);
            }
            if l + 1 < depth {
                parts = on.coarser_parts(l, rest.as_ref(), shapes[l + 1].1)?;
            }
        }
        Ok(on)
    }

    fn set_handover(&mut self, l: usize, level: Option<Level>) {
        if let (Some(h), Some(level)) = (self.handover[l].as_mut(), level) {
            h.level = Cow::Owned(level);
        }
    }

    /// Split level `l`'s operator on this rank's frame from the parts of its box: the
    /// couplings around the box from the neighbours, the diagonal, the diagonal around the
    /// box. Returns the level, with the absorption and patches coarsening reads; `None` on
    /// a rank that holds none of it.
    #[allow(clippy::type_complexity)]
    fn finish_split(
        &self,
        l: usize,
        parts: Option<LevelParts>,
        boundaries: &Boundaries,
    ) -> Result<Option<(Level, (Vec<f32>, Vec<LevelPatch>))>, DiffusionError> {
        let (frame, mut parts) = match (self.held[l].as_ref(), parts) {
            (Some(h), Some(p)) => (h.frame.clone(), p),
            (None, None) => return Ok(None),
            _ => return Err(protocol(self.rank, "a level's operator")),
        };
        for c in &mut parts.couplings {
            self.halo(l, c, f64::from, |v| v as f32, true, |_| ())?;
        }
        let LevelData {
            level,
            absorption,
            patches,
        } = parts.finish(boundaries);
        let Level {
            dims,
            spacing,
            couplings,
            mut diag,
            mut extra,
            mut inv_diag,
            ..
        } = level;
        for v in [&mut diag, &mut extra, &mut inv_diag] {
            self.halo(l, v, f64::from, |v| v as f32, true, |_| ())?;
        }
        let level =
            Level::new(dims, spacing, couplings, diag, extra, inv_diag).framed(frame.origin);
        Ok(Some((level, (absorption, patches))))
    }

    /// Level `l + 1`'s parts (cells of size `spacing`) on this rank's frame of it:
    /// coarsened from its own box of level `l` (`rest`: the absorption and patches of its
    /// frame) within a stage; where `l + 1` starts a stage, coarsened into the cells its
    /// box restricts to and handed to their owners in the next stage.
    fn coarser_parts(
        &self,
        l: usize,
        rest: Option<&(Vec<f32>, Vec<LevelPatch>)>,
        spacing: DVec3,
    ) -> Result<Option<LevelParts>, DiffusionError> {
        let coarsen = |onto: &Frame, region: &Region| -> Result<LevelParts, DiffusionError> {
            let (Some((absorption, patches)), Some(h)) = (rest, self.held[l].as_ref()) else {
                return Err(protocol(self.rank, "a level's coarsening"));
            };
            Ok(coarsen_in(
                (&h.level, absorption, patches),
                self.dims[l],
                h.frame.origin,
                onto.origin,
                onto.dims,
                region,
            ))
        };
        if !self.hands_over(l) {
            return match self.held[l + 1].as_ref() {
                Some(h) => coarsen(&h.frame, &self.owned(l + 1)).map(Some),
                None => Ok(None),
            };
        }
        // Across a stage boundary: the restricted cells, moved to the next stage's owners.
        let down = match self.handover[l + 1].as_ref() {
            Some(h) => Some((h.frame.clone(), coarsen(&h.frame, &self.restricts_to(l))?)),
            None => None,
        };
        let (fine_stage, coarse_stage) = (self.stage(l), self.stage(l + 1));
        let mut to = self.held[l + 1]
            .as_ref()
            .map(|h| (h.frame.clone(), LevelParts::zeros(h.frame.dims, spacing)));
        let have = |q: usize| fine_stage.owned(q, l + 1);
        let want = |q: usize| coarse_stage.owned(q, l + 1);
        let ranks = fine_stage.ranks();
        for field in 0..4 {
            let from = down.as_ref().map(|(f, p)| {
                let v = match field {
                    3 => &p.absorption[..],
                    axis => &p.couplings[axis][..],
                };
                (f, v)
            });
            let into = to.as_mut().map(|(f, p)| {
                let v = match field {
                    3 => &mut p.absorption[..],
                    axis => &mut p.couplings[axis][..],
                };
                (&*f, v)
            });
            self.move_regions(ranks, from, into, have, want)?;
        }
        let patches = self.move_patches(
            ranks,
            down.as_ref().map(|(f, p)| (f, &p.patches[..])),
            to.as_ref().map(|(f, _)| f),
            have,
            want,
        )?;
        Ok(to.map(|(_, mut p)| {
            p.patches = patches;
            p
        }))
    }

    /// Level `l`'s operator (it starts a stage: `level` on its owners' frames, the whole
    /// level on rank 0 for the serial stage; cells of size `spacing`) onto the previous
    /// stage's hand-over frames: the cells each rank's box restricts to and one around
    /// them. `None` on a rank that has no hand-over frame of level `l`.
    fn hand_up_operator(
        &self,
        l: usize,
        level: Option<&Level>,
        spacing: DVec3,
    ) -> Result<Option<Level>, DiffusionError> {
        let (fine_stage, coarse_stage) = (self.stage(l - 1), self.stage(l));
        let dims = self.dims[l];
        let from_frame = self.held[l].as_ref().map(|h| &h.frame);
        let to_frame = self.handover[l].as_ref().map(|h| &h.frame);
        let len = to_frame.map_or(0, Frame::len);
        let mut fields: [Vec<f32>; 6] = std::array::from_fn(|_| vec![0.0f32; len]);
        let sources: Option<[&[f32]; 6]> = match (level, from_frame) {
            (Some(lv), Some(_)) => Some([
                &lv.couplings[0][..],
                &lv.couplings[1][..],
                &lv.couplings[2][..],
                &lv.diag[..],
                &lv.extra[..],
                &lv.inv_diag[..],
            ]),
            (None, None) => None,
            _ => return Err(protocol(self.rank, "a coarse level's operator")),
        };
        for (i, field) in fields.iter_mut().enumerate() {
            let from = sources.zip(from_frame).map(|(s, f)| (f, s[i]));
            let to = to_frame.map(|f| (f, &mut field[..]));
            self.move_regions(
                fine_stage.ranks(),
                from,
                to,
                |q| coarse_stage.owned(q, l),
                |q| fine_stage.owned(q, l).grown(1, dims),
            )?;
        }
        Ok(to_frame.map(|frame| {
            let [c0, c1, c2, diag, extra, inv_diag] = fields;
            Level::new(frame.dims, spacing, [c0, c1, c2], diag, extra, inv_diag)
                .framed(frame.origin)
        }))
    }

    /// [`OnRanks::move_regions`] for boundary patches: each rank of 0..`ranks` sends each
    /// rank the patches of its `have` cells (in `from`, on its frame) that lie in that
    /// rank's `want` cells, and gets back its own, on its frame `to`, sorted by cell and
    /// side. A pair of ranks whose boxes overlap exchanges a message even when it holds no
    /// patch (so both know how many messages come).
    fn move_patches(
        &self,
        ranks: usize,
        from: Option<(&Frame, &[LevelPatch])>,
        to: Option<&Frame>,
        have: impl Fn(usize) -> Region,
        want: impl Fn(usize) -> Region,
    ) -> Result<Vec<LevelPatch>, DiffusionError> {
        if self.rank >= ranks {
            return Ok(Vec::new());
        }
        let mine = have(self.rank);
        let wanted = want(self.rank);
        let mut own: Vec<f64> = Vec::new();
        let mut parts: Vec<(usize, Vec<f64>)> = Vec::new();
        if let Some((frame, patches)) = from {
            for q in 0..ranks {
                let part = mine.overlap(&want(q));
                if part.is_empty() {
                    continue;
                }
                let mut words = Vec::new();
                for p in patches {
                    let at = level_cell(frame, p.cell);
                    if !contains(&part, at) {
                        continue;
                    }
                    let record: [f64; PATCH_WORDS] = [
                        at[0] as f64,
                        at[1] as f64,
                        at[2] as f64,
                        p.area,
                        p.distance,
                        p.normal.x,
                        p.normal.y,
                        p.normal.z,
                        p.diffusion,
                        side_code(p.side),
                        p.width,
                    ];
                    words.extend_from_slice(&record);
                }
                if q == self.rank {
                    own = words;
                } else {
                    parts.push((q, words));
                }
            }
        }
        let sends: Vec<(usize, &[f64])> = parts.iter().map(|(q, v)| (*q, &v[..])).collect();
        let sources: Vec<usize> = (0..ranks)
            .filter(|&q| q != self.rank && !have(q).overlap(&wanted).is_empty())
            .collect();
        let received = self.comm.exchange_with(&sends, &sources, &mut || ());
        if received.len() != sources.len() || (!sources.is_empty() && to.is_none()) {
            return Err(protocol(self.rank, "a coarse level's patches"));
        }
        let Some(frame) = to else {
            return Ok(Vec::new());
        };
        let held = Region::new(std::array::from_fn(|a| {
            frame.origin[a]..frame.origin[a] + frame.dims[a]
        }));
        let mut patches = Vec::new();
        for words in std::iter::once(&own).chain(&received) {
            if words.len() % PATCH_WORDS != 0 {
                return Err(protocol(self.rank, "a coarse level's patches"));
            }
            for w in words.chunks_exact(PATCH_WORDS) {
                let at = [w[0] as usize, w[1] as usize, w[2] as usize];
                let (Some(side), true) = (side_of(w[9]), contains(&held, at)) else {
                    return Err(protocol(self.rank, "a coarse level's patches"));
                };
                patches.push(LevelPatch {
                    cell: frame_index(frame, at),
                    area: w[3],
                    distance: w[4],
                    normal: DVec3::new(w[5], w[6], w[7]),
                    diffusion: w[8],
                    side,
                    width: w[10],
                });
            }
        }
        patches.sort_by_key(|p| (p.cell, p.side));
        Ok(patches)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::multigrid::{Cycle, Prolongation};
    use crate::problem::Condition;
    use crate::{CellGeometry, DiffusionProblem};
    use lucent_core::ranks::Threads;
    use lucent_grid::GridGeometry;

    fn field(n: usize, seed: u64, lo: f32, decades: f32) -> Vec<f32> {
        let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        (0..n)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                lo * 10f32.powf(decades * (state >> 40) as f32 / (1u64 << 24) as f32)
            })
            .collect()
    }

    /// Every frame a rank builds from its own fields (split levels, hand-over frames and
    /// rank 0's serial levels) equals the frame it extracts from the whole hierarchy, bit
    /// for bit: couplings, diagonals, spans and colour parity. Grids whose sides are not
    /// multiples of 8 or even, cut as slabs and boxes, with every level split (threshold
    /// 0: the most stages and hand-overs) and agglomerated; Robin, Dirichlet and Neumann
    /// faces (patches of every side merge on the coarse levels).
    #[test]
    fn every_frame_built_from_a_ranks_fields_is_the_whole_hierarchys() {
        let cases: [([usize; 3], usize, usize, Decomposition); 7] = [
            ([16, 12, 20], 2, 0, Decomposition::Slabs),
            ([16, 12, 20], 4, 0, Decomposition::Boxes),
            ([19, 13, 22], 3, 0, Decomposition::Boxes),
            ([24, 10, 9], 2, 0, Decomposition::Grid([2, 1, 1])),
            ([17, 20, 18], 6, 16, Decomposition::Boxes),
            ([16, 16, 16], 8, 0, Decomposition::Grid([2, 2, 2])),
            ([9, 7, 5], 1, 0, Decomposition::Slabs),
        ];
        for (case, (dims, ranks, coarse, decomposition)) in cases.into_iter().enumerate() {
            let geometry =
                GridGeometry::new(dims, DVec3::new(0.7, 0.5, 0.9), DVec3::new(-1.0, 0.2, 0.3))
                    .unwrap();
            let n = geometry.voxel_count();
            let seed = case as u64 + 11;
            let d = field(n, seed, 0.02, 2.0);
            let sigma_a = field(n, seed ^ 1, 0.001, 3.0);
            let q0 = field(n, seed ^ 2, 0.1, 1.0);
            let mut boundaries = Boundaries::uniform(Condition::Robin { a: 2.341 });
            boundaries.faces[1] = Condition::Dirichlet { value: 0.3 };
            boundaries.faces[4] = Condition::Neumann { flux: -0.2 };
            let problem = DiffusionProblem::new(
                CellGeometry::full_box(geometry),
                d.clone(),
                sigma_a.clone(),
                boundaries,
            )
            .unwrap();
            let settings = MultigridSettings {
                cycle: Cycle::V,
                prolongation: Prolongation::Trilinear,
                ..MultigridSettings::default()
            };
            let mg = Multigrid::build(&problem, settings).unwrap();
            let system = SlabSystem::new(geometry, boundaries).unwrap();
            let layout = mg.layout(ranks, coarse, decomposition).unwrap();
            assert_eq!(
                system
                    .multigrid_layout(&settings, ranks, coarse, decomposition)
                    .unwrap(),
                layout
            );
            let shapes = level_shapes(dims, geometry.spacing());
            assert_eq!(shapes.len(), mg.levels.len());
            let results = Threads::run(ranks, |comm| {
                let whole = OnRanks::new(&mg, comm, layout.clone());
                let reads = whole.owned(0).grown(1, dims);
                let (dp, sp, qp) = (
                    reads.cut(dims, &d),
                    reads.cut(dims, &sigma_a),
                    reads.cut(dims, &q0),
                );
                let fields = BlockFields {
                    origin: reads.axes.clone().map(|r| r.start),
                    dims: reads.axes.clone().map(|r| r.len()),
                    diffusion: &dp,
                    absorption: &sp,
                    source: &qp,
                };
                let local =
                    OnRanks::build(&system, &fields, &shapes, settings, comm, layout.clone())
                        .unwrap();
                let rank = comm.rank();
                for l in 0..mg.levels.len() {
                    if !whole.serial(l) {
                        let (a, b) = (&whole.held[l], &local.held[l]);
                        assert_eq!(
                            a.is_some(),
                            b.is_some(),
                            "case {case} rank {rank} level {l}"
                        );
                        if let (Some(a), Some(b)) = (a, b) {
                            assert_eq!(a.frame, b.frame);
                            assert!(a.level == b.level, "case {case} rank {rank} level {l}");
                        }
                    }
                    let (a, b) = (&whole.handover[l], &local.handover[l]);
                    assert_eq!(
                        a.is_some(),
                        b.is_some(),
                        "case {case} rank {rank} hand-over {l}"
                    );
                    if let (Some(a), Some(b)) = (a, b) {
                        assert!(a.level == b.level, "case {case} rank {rank} hand-over {l}");
                    }
                }
                let first = layout.stages.last().unwrap().first_level;
                match &local.serial {
                    Some(s) => {
                        assert_eq!((rank, s.first), (0, first));
                        assert!(s.mg.levels[..] == mg.levels[first..], "case {case}");
                    }
                    None => assert_ne!(rank, 0),
                }
            });
            assert!(
                results.iter().all(Option::is_some),
                "case {case}: a rank panicked"
            );
        }
    }
}
