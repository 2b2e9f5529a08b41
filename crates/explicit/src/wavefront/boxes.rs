//! Zhang & Ma's absorption march of a distant light over a Cartesian grid of boxes
//! ([`Boxes`]): the KBA sweep of discrete ordinates codes, for both one-pass models, any
//! light direction and any grid of boxes, with the serial march's bits.
//!
//! **The march's frame.** Every cell depends only on cells upwind of it, counted along
//! each axis from the face the light enters:
//!
//! - the paper's pass (Eq. 16): a cell reads its upwind neighbour along x, y and z (the
//!   light's density beyond an inflow face);
//! - short characteristics: a cell reads only the plane upstream across the light's
//!   dominant axis, at rows t − 2 … t + 1 along each lateral axis (the quadratic stencil
//!   reaches one row downwind).
//!
//! The cells fall into *planes* across an axis A and, within a plane, into *rows* along a
//! second axis L; D is the third. For characteristics A is the dominant axis and L the
//! lateral axis cut into the fewest boxes. The paper's cell reads along every axis alike,
//! so there L is the axis cut into the fewest boxes, and A the more cut of the other two.
//! Ties keep L off x, so that a task's cells run along x.
//!
//! **Tasks.** A rank's box is cut into tasks, each one plane by a *chunk* of rows by the
//! box's whole extent along D. A cell in plane m and row l belongs to chunk ⌊(l + s m)/B⌋:
//! the skew s is 1 for characteristics, so that a cell reading a row downwind still reads
//! an earlier chunk, and 0 for the paper. A rank runs its tasks chunk by chunk, each chunk
//! plane by plane; but where A is not cut, the characteristic's ranks run theirs plane by
//! plane (with no skew), all of them working on each plane together.
//!
//! B rows make a task hold at least [`TASK_CELLS`] cells, or [`STEP_CELLS`] where the
//! characteristic's boxes side by side along D advance a task per step in lock step.
//! Every task reads only cells of tasks earlier in its rank's order, or cells that other
//! ranks compute in tasks earlier in the global order (the same key, then boxes upwind
//! along L and D first). So the tasks form an acyclic graph across the ranks.
//!
//! **Steps.** Every rank derives the same schedule from the boxes and the light. It walks
//! all tasks in the global order and gives each a step: the step of its rank's previous
//! task while that step holds fewer than [`STEP_CELLS`] cells and every cell it reads from
//! another rank arrived before that step; otherwise the next step at which all of them
//! have arrived. At the end of step k each rank sends each rank that reads from it the
//! cells its step-k tasks computed that the other reads, one message per pair, and
//! receives likewise. Every send of step k is received in step k, by ranks that reach
//! step k after their own earlier steps, so the march cannot deadlock. Ranks with nothing
//! to send or receive skip the step. While a step's messages travel, a rank runs the
//! first tasks of its next step that read none of them (the schedule marks them).
//!
//! In lock step (the characteristic with the light's axis whole, ranks plane by plane) the
//! walk has a closed form: the tasks of plane m run in step m, after the exchange of every
//! rank's plane m − 1. There a rank derives only its own tasks, its partners (one pass
//! over the boxes) and the tasks of the ranks it reads from, not every rank's.
//!
//! **What overlaps.** This is a pipeline:
//! - a rank downstream along A starts its first chunk once the rank upstream has finished
//!   that chunk's last plane;
//! - boxes side by side along D work in lock step, or one task apart for the paper, as do
//!   boxes along L when the characteristic runs plane by plane.
//!
//! Cuts along L are not pipelined in chunk order: a box waits for the box upstream along
//! L to finish each plane's rows. So a grid cut along all three axes runs its L cuts one
//! after another; a grid that leaves one axis whole (one lateral axis, for
//! characteristics) is fully pipelined. The z-slab march ([`super::propagate_slab`]) is
//! the case of a grid cut only along z, specialised: one message per chunk of all its
//! layers, and the lock step's exchange overlapped with its inner rows.
//!
//! Every cell is computed by the serial pass's function (`Setup::characteristic_with`,
//! `convection::paper_cell`) from the same values, so ρ is the serial ρ bit for bit.
//! Memory per rank: ρ and σ_a over its box grown by [`HALO`] cells on every side
//! ([`read_box`]), plus the schedule (a few words per task: of every rank, or in lock step
//! of itself and the ranks it reads from).

use std::ops::Range;

use glam::DVec3;
use lucent_core::ranks::Communicator;
use lucent_grid::box_cells;
use rayon::prelude::*;

use crate::Lattice;
use crate::convection::{Light, Model, Setup, UpwindSettings, paper_cell};
use crate::ranks::{Boxes, DecompositionError, copy_cells};

/// A box of cells: its ranges along three axes (global x, y, z, or the march's A, L, D).
type Cells = [Range<usize>; 3];

/// How far beyond its box a rank reads σ_a and holds ρ: the two upwind rows of the
/// characteristic's quadratic stencil (its downwind row and the paper's upwind neighbour
/// lie within).
pub const HALO: usize = 2;

/// A task's rows are raised until it holds at least this many cells.
pub const TASK_CELLS: usize = 64;

/// A step takes a rank's next task while it holds fewer cells than this (about 130 µs on
/// a core at 0.25 µs per cell, well above a message's latency).
pub const STEP_CELLS: usize = 512;

/// Every rank derives every rank's tasks (about 40 bytes each), so chunks are widened
/// until the march has about this many tasks at most (40 MiB): on a 1024³ grid, chunks of
/// 9 rows at 64 ranks (8 × 8 × 1 boxes), and at 1024 (32 × 32 × 1) of 34 rows, or a whole
/// plane of each box where that is already a million tasks (`docs/ranks.md`, section 4).
pub const MAX_TASKS: usize = 1 << 20;

/// The cells rank `rank` of `boxes` reads (σ_a) and holds (ρ): its box grown by [`HALO`]
/// cells on every side, within the grid.
pub fn read_box(boxes: &Boxes, rank: usize) -> Cells {
    let dims = boxes.dims();
    let own = boxes.bounds(rank);
    std::array::from_fn(|a| own[a].start.saturating_sub(HALO)..(own[a].end + HALO).min(dims[a]))
}

/// The intersection of two boxes (empty ranges where they miss).
fn meet(a: &Cells, b: &Cells) -> Cells {
    std::array::from_fn(|i| {
        let start = a[i].start.max(b[i].start);
        start..a[i].end.min(b[i].end).max(start)
    })
}

fn is_empty(cells: &Cells) -> bool {
    cells.iter().any(Range::is_empty)
}

fn count(cells: &Cells) -> usize {
    cells.iter().map(Range::len).product()
}

/// The march's frame: which global axes are A, L and D, and which way the light goes.
#[derive(Debug, Clone, Copy)]
struct Frame {
    /// The global axes of A (planes), L (chunked rows) and D.
    axes: [usize; 3],
    /// Per global axis, whether the light's order is the index order.
    forward: [bool; 3],
    dims: [usize; 3],
    /// 1 for characteristics (chunks skewed by the plane), 0 for the paper.
    skew: usize,
    /// Rows per chunk.
    rows: usize,
    /// Whether a rank runs its tasks plane by plane (else chunk by chunk).
    plane_major: bool,
}

impl Frame {
    /// `range` along global axis `a` in the light's order; its own inverse.
    fn flip(&self, a: usize, range: Range<usize>) -> Range<usize> {
        if self.forward[a] {
            range
        } else {
            self.dims[a] - range.end..self.dims[a] - range.start
        }
    }

    /// A box of global cells in the march's coordinates [A, L, D].
    fn march_cells(&self, cells: &Cells) -> Cells {
        std::array::from_fn(|i| self.flip(self.axes[i], cells[self.axes[i]].clone()))
    }

    /// A box in the march's coordinates as global cells.
    fn global_cells(&self, march: &Cells) -> Cells {
        let mut out = [0..0, 0..0, 0..0];
        for (i, range) in march.iter().enumerate() {
            out[self.axes[i]] = self.flip(self.axes[i], range.clone());
        }
        out
    }

    /// The chunk of the cell in plane `plane`, row `row`.
    fn chunk(&self, plane: usize, row: usize) -> usize {
        (row + self.skew * plane) / self.rows
    }

    /// Where the task of the cells of chunk `chunk` in plane `plane` comes in its rank's
    /// order, and in the global one.
    fn key(&self, chunk: usize, plane: usize) -> (usize, usize) {
        if self.plane_major {
            (plane, chunk)
        } else {
            (chunk, plane)
        }
    }
}

/// One plane of a chunk of a box: cells `rows` (along L, march coordinates) of plane
/// `plane` across the box's extent along D.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Task {
    chunk: usize,
    plane: usize,
    rows: Range<usize>,
    step: usize,
    /// Whether it reads cells that arrive at the end of the step before its own (else it
    /// can run while those messages travel).
    waits: bool,
}

/// Where a rank's task of a given key is in its order: the tasks of one major key (a
/// chunk, or a plane where ranks run plane by plane) are consecutive, their minor keys
/// consecutive too.
struct TaskIndex {
    first_major: usize,
    /// Per major key from `first_major`: its first minor key and its first task.
    runs: Vec<(usize, usize)>,
    tasks: usize,
}

impl TaskIndex {
    fn new(frame: &Frame, tasks: &[Task]) -> Self {
        let first_major = tasks.first().map_or(0, |t| frame.key(t.chunk, t.plane).0);
        let mut runs: Vec<(usize, usize)> = Vec::new();
        for (i, t) in tasks.iter().enumerate() {
            let (major, minor) = frame.key(t.chunk, t.plane);
            if runs.len() <= major - first_major {
                runs.resize(major - first_major + 1, (usize::MAX, i));
                runs[major - first_major] = (minor, i);
            }
        }
        Self {
            first_major,
            runs,
            tasks: tasks.len(),
        }
    }

    /// The task of key `(major, minor)`, where its major key's run holds it.
    fn find(&self, (major, minor): (usize, usize)) -> Option<usize> {
        let slot = major.checked_sub(self.first_major)?;
        let &(first_minor, start) = self.runs.get(slot)?;
        let end = self.runs.get(slot + 1).map_or(self.tasks, |r| r.1);
        let at = start + minor.checked_sub(first_minor)?;
        (at < end).then_some(at)
    }
}

/// Every rank's tasks and steps, and who reads from whom: the same on every rank.
#[derive(Debug)]
struct Plan {
    frame: Frame,
    model: Model,
    /// Each rank's box in march coordinates.
    boxes: Vec<Cells>,
    /// Each rank's tasks, in its order (steps non-decreasing).
    tasks: Vec<Vec<Task>>,
    /// Per rank, boxes (march coordinates) holding every cell outside its box that its
    /// tasks read, disjoint.
    needs: Vec<Vec<Cells>>,
    /// Per rank, the ranks it reads from, and the ranks that read from it, ascending.
    fed_by: Vec<Vec<usize>>,
    feeds: Vec<Vec<usize>>,
    steps: usize,
}

impl Plan {
    /// The schedule of the march of a light going along `direction` (normalised) with
    /// `model` over `boxes`, in about [`MAX_TASKS`] tasks at most: every rank's.
    fn new(boxes: &Boxes, direction: DVec3, model: Model) -> Result<Self, DecompositionError> {
        Self::with_limit(boxes, direction, model, MAX_TASKS, None)
    }

    /// The part of [`Plan::new`]'s schedule that rank `rank` marches by: in lock step (the
    /// characteristic with the light's axis whole) its own tasks and those of the ranks it
    /// reads from, and who reads from it (the steps have a closed form: nothing to walk);
    /// otherwise every rank's (the pipeline's steps come from a walk of all tasks).
    fn for_rank(
        boxes: &Boxes,
        direction: DVec3,
        model: Model,
        rank: usize,
    ) -> Result<Self, DecompositionError> {
        Self::with_limit(boxes, direction, model, MAX_TASKS, Some(rank))
    }

    /// [`Plan::new`] with chunks wide enough for about `max_tasks` tasks at most; with
    /// `only`, [`Plan::for_rank`]'s part of it.
    fn with_limit(
        boxes: &Boxes,
        direction: DVec3,
        model: Model,
        max_tasks: usize,
        only: Option<usize>,
    ) -> Result<Self, DecompositionError> {
        let dims = boxes.dims();
        let grid = boxes.grid();
        let size = boxes.ranks();
        // Which axes, and the order: see the module's docs.
        let fewest = |axes: &[usize]| {
            *axes
                .iter()
                .min_by_key(|&&a| (grid[a], a == 0, a))
                .unwrap_or(&axes[0])
        };
        let (axes, skew, plane_major) = match model {
            Model::Paper => {
                // Any axis can be A: the paper's cell reads upwind along all three.
                let along = fewest(&[0, 1, 2]);
                let others = [(along + 1) % 3, (along + 2) % 3];
                let planes = *others
                    .iter()
                    .max_by_key(|&&a| (grid[a], a))
                    .unwrap_or(&others[0]);
                ([planes, along, 3 - planes - along], 0, false)
            }
            _ => {
                let planes = direction.abs().max_position();
                let along = fewest(&[(planes + 1) % 3, (planes + 2) % 3]);
                let plane_major = grid[planes] == 1;
                let skew = usize::from(!plane_major);
                ([planes, along, 3 - planes - along], skew, plane_major)
            }
        };
        // Boxes side by side along D run a characteristic's chunks in lock step, a task
        // per step: there a task holds a step's cells.
        let lock_step = skew == 1 && grid[axes[2]] > 1;
        let cells = if lock_step { STEP_CELLS } else { TASK_CELLS };
        let width = (dims[axes[2]] / grid[axes[2]]).max(1);
        // Every rank holds every rank's tasks: about n_A p_D (n_L/B + p_L) of them (each
        // box's plane cut into chunks), kept to `max_tasks` by wider chunks.
        let [n_a, n_l, _] = axes.map(|a| dims[a]);
        let columns = n_a * grid[axes[2]];
        let one_chunk_each = columns * grid[axes[1]];
        let rows = if one_chunk_each >= max_tasks {
            n_l
        } else {
            cells
                .div_ceil(width)
                .max((columns * n_l).div_ceil(max_tasks - one_chunk_each))
        };
        let frame = Frame {
            axes,
            forward: std::array::from_fn(|a| direction[a] >= 0.0),
            dims,
            skew,
            rows: rows.clamp(1, n_l.max(1)),
            plane_major,
        };
        let march_dims = frame.axes.map(|a| dims[a]);
        let own: Vec<Cells> = (0..size)
            .map(|r| frame.march_cells(&boxes.bounds(r)))
            .collect();
        let needs: Vec<Vec<Cells>> = own
            .iter()
            .map(|b| {
                reads(model, march_dims, b, b[0].clone(), b[1].clone())
                    .into_iter()
                    .filter(|n| !is_empty(n))
                    .collect()
            })
            .collect();
        let mut fed_by = vec![Vec::new(); size];
        let mut feeds = vec![Vec::new(); size];
        let reads_from =
            |x: usize, q: usize| q != x && needs[x].iter().any(|n| !is_empty(&meet(n, &own[q])));
        // In lock step a rank needs only its own pairs (each rank's steps are its planes);
        // the pipeline's walk needs every rank's.
        let lock_step_planes = plane_major && size > 1;
        match only.filter(|_| lock_step_planes) {
            Some(me) => {
                fed_by[me] = (0..size).filter(|&q| reads_from(me, q)).collect();
                feeds[me] = (0..size).filter(|&x| reads_from(x, me)).collect();
            }
            None => {
                for x in 0..size {
                    for q in 0..size {
                        if reads_from(x, q) {
                            fed_by[x].push(q);
                            feeds[q].push(x);
                        }
                    }
                }
            }
        }
        let mut tasks: Vec<Vec<Task>> = (0..size)
            .map(|r| {
                let needed = match only.filter(|_| lock_step_planes) {
                    Some(me) => r == me || fed_by[me].contains(&r),
                    None => true,
                };
                if needed {
                    frame.tasks_of(&own[r])
                } else {
                    Vec::new()
                }
            })
            .collect();
        if lock_step_planes {
            // The light's axis is whole, so every rank holds every plane, and a
            // characteristic's plane reads only the plane before it. The steps have a
            // closed form: each box's rows of a plane fall into groups of whole chunks,
            // about `STEP_CELLS` cells each, at most `groups` per box, and a box's group g
            // of plane m runs in step m · groups + g. A task reads plane m − 1 only, all
            // of whose steps come before its own; it waits for the exchange that ends the
            // step before its own if it reads a cell another rank computed in that step
            // (known for the ranks whose partners were found: all, or `only`, the one
            // whose tasks run).
            let per_group = STEP_CELLS.div_ceil(width).div_ceil(frame.rows).max(1);
            let first_chunk = |r: usize| own[r][1].start / frame.rows;
            let groups = (0..size)
                .map(|r| {
                    let chunks = own[r][1].end.div_ceil(frame.rows) - first_chunk(r);
                    chunks.div_ceil(per_group)
                })
                .max()
                .unwrap_or(1)
                .max(1);
            let step_of = |r: usize, plane: usize, row: usize| {
                plane * groups + (row / frame.rows - first_chunk(r)) / per_group
            };
            for (r, tasks) in tasks.iter_mut().enumerate() {
                for task in tasks.iter_mut() {
                    task.step = step_of(r, task.plane, task.rows.start);
                    let read = reads(
                        model,
                        march_dims,
                        &own[r],
                        task.plane..task.plane + 1,
                        task.rows.clone(),
                    );
                    let latest = read
                        .iter()
                        .flat_map(|read| fed_by[r].iter().map(|&q| (q, meet(read, &own[q]))))
                        .filter(|(_, cells)| !is_empty(cells))
                        .map(|(q, cells)| step_of(q, cells[0].end - 1, cells[1].end - 1))
                        .max();
                    task.waits = latest.is_some_and(|s| s + 1 == task.step);
                }
            }
            return Ok(Self {
                frame,
                model,
                boxes: own,
                tasks,
                needs,
                fed_by,
                feeds,
                steps: march_dims[0] * groups,
            });
        }
        // Steps: every task in the global order (its dependencies first).
        // The sort key packed with the task (a sort of plain words: the tasks of a 1024³
        // grid on 1024 ranks number a million).
        let mut order: Vec<([usize; 4], usize)> = (0..size)
            .flat_map(|r| {
                let upwind = own[r][1].start + own[r][2].start;
                tasks[r].iter().enumerate().map(move |(i, t)| {
                    let (major, minor) = frame.key(t.chunk, t.plane);
                    ([major, minor, upwind, r], i)
                })
            })
            .collect();
        order.sort_unstable_by_key(|&(key, _)| key);
        let index: Vec<TaskIndex> = tasks.iter().map(|t| TaskIndex::new(&frame, t)).collect();
        let mut scheduled: Vec<usize> = vec![0; size];
        let mut current: Vec<(usize, usize)> = vec![(0, 0); size];
        let mut steps = 0;
        for ([.., r], i) in order {
            let task = &tasks[r][i];
            let mine = [
                task.plane..task.plane + 1,
                task.rows.clone(),
                own[r][2].clone(),
            ];
            let mut ready = 0;
            let read = reads(model, march_dims, &own[r], mine[0].clone(), mine[1].clone());
            for &q in &fed_by[r] {
                for read in &read {
                    let cells = meet(read, &own[q]);
                    if is_empty(&cells) {
                        continue;
                    }
                    // The latest of q's tasks these cells come from: q's steps rise with
                    // its order, which is the order of the keys.
                    let (plane, row) = (cells[0].end - 1, cells[1].end - 1);
                    let key = frame.key(frame.chunk(plane, row), plane);
                    let Some(at) = index[q]
                        .find(key)
                        .filter(|&at| frame.key(tasks[q][at].chunk, tasks[q][at].plane) == key)
                    else {
                        return Err(DecompositionError::Protocol { rank: q });
                    };
                    if at >= scheduled[q] {
                        // Not scheduled yet: the global order is broken.
                        return Err(DecompositionError::Protocol { rank: q });
                    }
                    ready = ready.max(tasks[q][at].step + 1);
                }
            }
            let (step, held) = current[r];
            let cells = task.rows.len() * own[r][2].len();
            let next = if scheduled[r] > 0 && ready <= step && held < STEP_CELLS {
                (step, held + cells)
            } else if scheduled[r] == 0 {
                (ready, cells)
            } else {
                (ready.max(step + 1), cells)
            };
            current[r] = next;
            tasks[r][i].step = next.0;
            tasks[r][i].waits = ready > 0 && ready == next.0;
            if i != scheduled[r] {
                return Err(DecompositionError::Protocol { rank: r });
            }
            scheduled[r] += 1;
            steps = steps.max(next.0 + 1);
        }
        Ok(Self {
            frame,
            model,
            boxes: own,
            tasks,
            needs,
            fed_by,
            feeds,
            steps,
        })
    }

    /// The cells (global, in the order both sides agree on) that rank `from`'s `tasks`
    /// compute and rank `to` reads.
    fn transfer<'a>(
        &'a self,
        tasks: &'a [Task],
        from: usize,
        to: usize,
    ) -> impl Iterator<Item = [usize; 3]> + 'a {
        self.transfer_boxes(tasks, from, to)
            .flat_map(|cells| box_cells(&cells))
    }

    /// [`Plan::transfer`]'s cells as boxes of global cells, some empty.
    fn transfer_boxes<'a>(
        &'a self,
        tasks: &'a [Task],
        from: usize,
        to: usize,
    ) -> impl Iterator<Item = Cells> + 'a {
        tasks.iter().flat_map(move |t| {
            let cells = self.cells_of(t, from);
            self.needs[to]
                .iter()
                .map(move |n| self.frame.global_cells(&meet(&cells, n)))
        })
    }

    /// Task `task` of rank `rank`'s cells in march coordinates.
    fn cells_of(&self, task: &Task, rank: usize) -> Cells {
        [
            task.plane..task.plane + 1,
            task.rows.clone(),
            self.boxes[rank][2].clone(),
        ]
    }
}

impl Frame {
    /// The tasks of a box (march coordinates) in its rank's order, steps unset.
    fn tasks_of(&self, own: &Cells) -> Vec<Task> {
        let [planes, rows, _] = own;
        if is_empty(own) {
            return Vec::new();
        }
        let first = self.chunk(planes.start, rows.start);
        let last = self.chunk(planes.end - 1, rows.end - 1);
        let mut out = Vec::new();
        for chunk in first..=last {
            for plane in planes.clone() {
                let shift = self.skew * plane;
                let lo = (chunk * self.rows).saturating_sub(shift).max(rows.start);
                let hi = ((chunk + 1) * self.rows)
                    .saturating_sub(shift)
                    .min(rows.end);
                if lo < hi {
                    out.push(Task {
                        chunk,
                        plane,
                        rows: lo..hi,
                        step: 0,
                        waits: false,
                    });
                }
            }
        }
        out.sort_by_key(|t| self.key(t.chunk, t.plane));
        out
    }
}

/// The cells (march coordinates) that the cells `planes` × `rows` × the box's D extent
/// read, for the box `own`: the upstream planes grown by the stencil for
/// characteristics; for the paper, the region shifted one cell upwind along each axis.
/// The boxes overlap only in cells of the region itself, so their parts in another
/// rank's box are disjoint.
fn reads(
    model: Model,
    dims: [usize; 3],
    own: &Cells,
    planes: Range<usize>,
    rows: Range<usize>,
) -> Vec<Cells> {
    let across = own[2].clone();
    let upwind = |r: &Range<usize>| r.start.saturating_sub(1)..r.end.saturating_sub(1);
    match model {
        Model::Paper => vec![
            [upwind(&planes), rows.clone(), across.clone()],
            [planes.clone(), upwind(&rows), across.clone()],
            [planes, rows, upwind(&across)],
        ],
        _ => vec![[
            upwind(&planes),
            rows.start.saturating_sub(2)..(rows.end + 1).min(dims[1]),
            across.start.saturating_sub(2)..(across.end + 1).min(dims[2]),
        ]],
    }
}

/// The grid of `ranks` boxes over `dims` cells that suits the march of a distant light
/// along `direction` with `model`: the least cut area ([`Boxes::auto`]) among the grids
/// that leave an axis whole, so that the sweep is pipelined across every cut (the
/// module's docs). For characteristics the light's dominant axis first (then every rank
/// works on every plane, in lock step), then either lateral one; for the paper any axis.
/// [`Boxes::auto`]'s grid where none fits.
///
/// # Errors
/// [`DecompositionError::BoxGrid`] if no grid of `ranks` boxes fits.
pub fn march_boxes(
    dims: [usize; 3],
    ranks: usize,
    direction: DVec3,
    model: Model,
) -> Result<Boxes, DecompositionError> {
    let any = || Boxes::auto_leaving_whole(dims, ranks, &[0, 1, 2]);
    match model {
        Model::Paper => any(),
        _ => {
            let planes = direction.normalize_or_zero().abs().max_position();
            Boxes::auto_leaving_whole(dims, ranks, &[planes]).or_else(|_| any())
        }
    }
    .or_else(|_| Boxes::auto(dims, ranks))
}

/// The shape of the march over boxes, for a cost model ([`box_schedule`]): the frame and
/// chunks it chose, how many steps it takes and what each rank does in them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BoxSchedule {
    /// The global axes (0 = x) of the planes (A), the chunked rows (L) and the rest (D).
    pub axes: [usize; 3],
    /// Rows per chunk.
    pub rows: usize,
    /// Whether the ranks run their tasks plane by plane (else chunk by chunk).
    pub plane_major: bool,
    /// Steps of the whole march: each ends in one exchange among the ranks that send or
    /// receive in it.
    pub steps: usize,
    /// Per rank, its tasks.
    pub tasks: Vec<usize>,
    /// Per rank, the steps it computes in.
    pub busy: Vec<usize>,
    /// Per rank, the messages it sends (one per step and rank that reads from it).
    pub messages: Vec<usize>,
    /// Per rank, the values (f64) it sends.
    pub values: Vec<usize>,
}

/// The schedule [`propagate_box`] follows for a distant light along `direction` with
/// `model` over `boxes` (no march is run). The same on every rank.
///
/// # Errors
/// [`DecompositionError::Unsupported`] for a model that does not split (only the paper's
/// and the characteristic one-pass marches do); [`DecompositionError::Protocol`] if the
/// schedule cannot be built (not expected).
pub fn box_schedule(
    boxes: &Boxes,
    direction: DVec3,
    model: Model,
) -> Result<BoxSchedule, DecompositionError> {
    let direction = direction.normalize_or_zero();
    if model == Model::Conservative || direction == DVec3::ZERO || !direction.is_finite() {
        return Err(DecompositionError::Unsupported(format!(
            "the {model:?} march along {direction} over boxes"
        )));
    }
    let plan = Plan::new(boxes, direction, model)?;
    let size = plan.tasks.len();
    let mut messages = vec![0; size];
    let mut values = vec![0; size];
    let mut busy = vec![0; size];
    for rank in 0..size {
        let tasks = &plan.tasks[rank];
        let mut first = 0;
        while first < tasks.len() {
            let step = tasks[first].step;
            let end = first + tasks[first..].partition_point(|t| t.step == step);
            busy[rank] += 1;
            for &to in &plan.feeds[rank] {
                let sent: usize = plan
                    .transfer_boxes(&tasks[first..end], rank, to)
                    .map(|cells| count(&cells))
                    .sum();
                if sent > 0 {
                    messages[rank] += 1;
                    values[rank] += sent;
                }
            }
            first = end;
        }
    }
    Ok(BoxSchedule {
        axes: plan.frame.axes,
        rows: plan.frame.rows,
        plane_major: plan.frame.plane_major,
        steps: plan.steps,
        tasks: plan.tasks.iter().map(Vec::len).collect(),
        busy,
        messages,
        values,
    })
}

/// How many tasks rank `rank` derives before it marches a distant light along
/// `direction` with `model` over `boxes` (its part of the schedule, [`propagate_box`]'s
/// first step): in lock step (the characteristic with the light's axis whole) its own and
/// those of the ranks it reads from; otherwise every rank's, since the pipeline's steps
/// come from a walk of them all.
///
/// # Errors
/// As [`box_schedule`]; [`DecompositionError::BoxGrid`] for a rank the boxes do not have.
pub fn rank_plan_tasks(
    boxes: &Boxes,
    direction: DVec3,
    model: Model,
    rank: usize,
) -> Result<usize, DecompositionError> {
    let direction = direction.normalize_or_zero();
    if model == Model::Conservative || direction == DVec3::ZERO || !direction.is_finite() {
        return Err(DecompositionError::Unsupported(format!(
            "the {model:?} march along {direction} over boxes"
        )));
    }
    if rank >= boxes.ranks() {
        return Err(DecompositionError::BoxGrid {
            grid: boxes.grid(),
            dims: boxes.dims(),
            ranks: rank + 1,
        });
    }
    let plan = Plan::for_rank(boxes, direction, model, rank)?;
    Ok(plan.tasks.iter().map(Vec::len).sum())
}

/// A rank's fields over its [`read_box`]: cell (x, y, z) at its offset from the box's
/// corner, x fastest.
struct Local {
    region: Cells,
    rho: Vec<f64>,
}

impl Local {
    fn at(&self, p: [usize; 3]) -> usize {
        local_index(&self.region, p)
    }
}

/// Where cell `p` lies in fields that hold the box `region`, x fastest.
fn local_index(region: &Cells, p: [usize; 3]) -> usize {
    (p[0] - region[0].start)
        + region[0].len() * ((p[1] - region[1].start) + region[1].len() * (p[2] - region[2].start))
}

/// The march of [`super::propagate_on_ranks`] over the grid of boxes `boxes` (one per
/// rank), holding only this rank's [`read_box`]: `absorption` is σ_a there (x fastest),
/// and the result ρ of the rank's box (`boxes.bounds(rank)`, x fastest), the serial
/// march's bits there. The one-pass marches of a distant light only (ordered sweeps,
/// inflow edges, the paper's or the characteristic model); `settings.initial` is
/// ignored. Every rank checks its absorption and all agree before marching, so a bad
/// value on one rank stops every rank with an error, never a hang.
///
/// # Errors
/// [`DecompositionError::BoxGrid`] for boxes that are not a grid of the lattice's cells
/// with one box per rank; [`DecompositionError::Unsupported`] for a march that does not
/// split; the march's own refusals ([`DecompositionError::Scheme`]);
/// [`DecompositionError::Protocol`] if a rank sent what the plan did not expect.
pub fn propagate_box(
    lattice: &Lattice,
    absorption: &[f64],
    light: &Light,
    settings: &UpwindSettings,
    boxes: &Boxes,
    comm: &(impl Communicator + ?Sized),
) -> Result<Vec<f64>, DecompositionError> {
    let (size, rank) = (comm.size(), comm.rank());
    if boxes.ranks() != size || boxes.dims() != lattice.dims {
        return Err(DecompositionError::BoxGrid {
            grid: boxes.grid(),
            dims: lattice.dims,
            ranks: size,
        });
    }
    if !super::splits(light, settings) {
        if size <= 1 {
            let serial = crate::convection::propagate(lattice, absorption, light, settings)?;
            return Ok(serial.density);
        }
        return Err(super::unsupported(light));
    }
    let region = read_box(boxes, rank);
    let setup = super::checked_part(lattice, absorption, light, settings, comm, |len| {
        (len != count(&region)).then(|| format!("{len} values for the cells {region:?}"))
    })?;
    let Light::Distant { direction, density } = setup.light else {
        return Err(super::unsupported(light));
    };
    let plan = Plan::for_rank(boxes, direction, setup.model, rank)?;
    let mut local = Local {
        rho: vec![0.0; count(&region)],
        region,
    };
    let mine = &plan.tasks[rank];
    let fed_by = &plan.fed_by[rank];
    // Per rank this one reads from: where its tasks of the current step start.
    let mut cursors = vec![0usize; fed_by.len()];
    // This rank's tasks of the current step start at `first`; those before `next` are done
    // (some ran while the previous step's messages travelled).
    let (mut first, mut next) = (0, 0);
    let protocol = DecompositionError::Protocol { rank };
    let light = (direction, density);
    for step in 0..plan.steps {
        while next < mine.len() && mine[next].step == step {
            run(&setup, &plan, rank, &mine[next], light, &mut local);
            next += 1;
        }
        let done = &mine[first..next];
        first = next;
        let sends: Vec<(usize, Vec<f64>)> = plan.feeds[rank]
            .iter()
            .map(|&to| {
                let values: Vec<f64> = plan
                    .transfer(done, rank, to)
                    .map(|p| local.rho[local.at(p)])
                    .collect();
                (to, values)
            })
            .filter(|(_, values)| !values.is_empty())
            .collect();
        let mut from = Vec::new();
        let mut theirs = Vec::new();
        for (cursor, &q) in cursors.iter_mut().zip(fed_by) {
            let start = *cursor;
            let tasks = &plan.tasks[q];
            while *cursor < tasks.len() && tasks[*cursor].step == step {
                *cursor += 1;
            }
            let sent = &tasks[start..*cursor];
            if plan.transfer(sent, q, rank).next().is_some() {
                from.push(q);
                theirs.push(sent);
            }
        }
        if sends.is_empty() && from.is_empty() {
            continue;
        }
        let sends: Vec<(usize, &[f64])> = sends.iter().map(|(to, v)| (*to, &v[..])).collect();
        // While the messages travel: the next step's first tasks that need none of them
        // (they write only this rank's cells, the messages only its halo).
        let received = comm.exchange_with(&sends, &from, &mut || {
            while next < mine.len() && mine[next].step == step + 1 && !mine[next].waits {
                run(&setup, &plan, rank, &mine[next], light, &mut local);
                next += 1;
            }
        });
        if received.len() != from.len() {
            return Err(protocol);
        }
        for ((values, &q), sent) in received.iter().zip(&from).zip(theirs) {
            let mut values = values.iter();
            for p in plan.transfer(sent, q, rank) {
                let at = local.at(p);
                local.rho[at] = *values.next().ok_or(protocol.clone())?;
            }
            if values.next().is_some() {
                return Err(protocol);
            }
        }
    }
    if next != mine.len() {
        return Err(protocol);
    }
    let own = boxes.bounds(rank);
    let mut out = vec![0.0; count(&own)];
    copy_cells(&local.rho, &local.region, &mut out, &own, &own);
    Ok(out)
}

/// Computes task `task` of rank `rank` into `local`.
fn run(
    setup: &Setup<'_>,
    plan: &Plan,
    rank: usize,
    task: &Task,
    (direction, density): (DVec3, f64),
    local: &mut Local,
) {
    let frame = &plan.frame;
    let march = plan.cells_of(task, rank);
    let region = &local.region;
    // Strides of the rank's fields along x, y and z.
    let stride = [1, region[0].len(), region[0].len() * region[1].len()];
    match plan.model {
        Model::Paper => {
            // Row by row in the light's order along L, each row along D in the light's
            // order (one plane): every cell after its upwind neighbours along x, y and z.
            let w = direction.abs();
            let total = w.element_sum();
            let [planes, along, across] = frame.axes;
            // Per axis, the step from a cell to its upwind neighbour in the fields, and
            // whether the cells at `at` lie on the face the light enters.
            let upwind: [isize; 3] = std::array::from_fn(|a| {
                let step = stride[a] as isize;
                if frame.forward[a] { -step } else { step }
            });
            let entering = |a: usize, at: &[usize; 3]| {
                at[a]
                    == if frame.forward[a] {
                        0
                    } else {
                        frame.dims[a] - 1
                    }
            };
            let mut at = [0usize; 3];
            for (i, range) in march.iter().enumerate() {
                at[frame.axes[i]] = frame
                    .flip(frame.axes[i], range.start..range.start + 1)
                    .start;
            }
            for row in march[1].clone() {
                at[along] = frame.flip(along, row..row + 1).start;
                let mut here = local.at(at) as isize;
                let rho = &mut local.rho;
                // Along A and L the whole row reads its neighbours at one offset, or the
                // light's density; along D each cell reads the one before it.
                let from = |a: usize| (!entering(a, &at)).then_some(upwind[a]);
                let (from_plane, from_row) = (from(planes), from(along));
                let mut before = match from(across) {
                    Some(offset) => rho[(here + offset) as usize],
                    None => density,
                };
                for _ in march[2].clone() {
                    let mut inflow = [0.0; 3];
                    inflow[planes] = from_plane.map_or(density, |o| rho[(here + o) as usize]);
                    inflow[along] = from_row.map_or(density, |o| rho[(here + o) as usize]);
                    inflow[across] = before;
                    let cell = here as usize;
                    before = paper_cell(
                        setup.courant,
                        (w, total),
                        inflow,
                        setup.absorption[cell],
                        rho[cell],
                    );
                    rho[cell] = before;
                    // The next cell along D, downwind.
                    here -= upwind[across];
                }
            }
        }
        _ => {
            // Reads only the upstream plane: compute the task's cells, then store them.
            let cells = frame.global_cells(&march);
            let index = |p: [usize; 3]| local_index(region, p);
            let rho = &local.rho;
            let compute = |p: [usize; 3]| {
                setup.characteristic_at(p, &index, &|i| rho[i], &|i| setup.absorption[i])
            };
            let values: Vec<f64> = if count(&cells) >= 4 * STEP_CELLS {
                let points: Vec<[usize; 3]> = box_cells(&cells).collect();
                points.into_par_iter().map(compute).collect()
            } else {
                box_cells(&cells).map(compute).collect()
            };
            for (p, v) in box_cells(&cells).zip(values) {
                local.rho[index(p)] = v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The steps of the march over `grid` boxes of a 64³ grid, and the most any rank
    /// computes in (each step holds about [`STEP_CELLS`] cells of a rank's work).
    fn steps(grid: [usize; 3], u: DVec3, model: Model) -> (usize, usize) {
        let boxes = Boxes::new([64; 3], grid).unwrap();
        let plan = Plan::new(&boxes, u.normalize(), model).unwrap();
        let busy = plan.tasks.iter().map(|tasks| {
            let mut steps: Vec<usize> = tasks.iter().map(|t| t.step).collect();
            steps.dedup();
            steps.len()
        });
        (plan.steps, busy.max().unwrap_or(0))
    }

    /// The schedule overlaps the ranks' work: against the steps a rank is busy, the
    /// march takes at most 5 % more where the cuts run in lock step or one task apart,
    /// and at most twice as many where a characteristic's pipeline crosses cuts along
    /// the light (each rank starts a slab's depth after the one upstream). Ranks one
    /// after another would take P times as many.
    #[test]
    fn the_schedule_overlaps_the_ranks() {
        let z = DVec3::new(0.1, 0.2, 1.0);
        let x = DVec3::new(1.0, 0.2, 0.1);
        let one = steps([1, 1, 1], z, Model::Characteristic);
        assert_eq!(one, (512, 512));
        for (grid, u, model, most) in [
            // Lock step across cuts beside the light; the paper one task apart.
            ([2, 2, 1], z, Model::Characteristic, 1.05),
            ([1, 1, 4], x, Model::Characteristic, 1.05),
            ([2, 2, 1], z, Model::Paper, 1.05),
            ([1, 1, 4], z, Model::Paper, 1.05),
            ([2, 1, 2], z, Model::Paper, 1.05),
            // The characteristic's pipeline along the light.
            ([1, 1, 4], z, Model::Characteristic, 2.0),
            ([2, 1, 2], z, Model::Characteristic, 2.0),
        ] {
            let (total, busy) = steps(grid, u, model);
            assert!(
                busy <= 512 / grid.iter().product::<usize>() + 32,
                "{grid:?} {u} {model:?}: {busy}"
            );
            assert!(
                total as f64 <= most * busy as f64,
                "{grid:?} {u} {model:?}: {total} steps, {busy} busy"
            );
        }
    }

    /// What crosses a cut is exactly what the stencil reads: the paper's and the
    /// characteristic's upstream plane where the light crosses the cut, and where it runs
    /// along it the characteristic's two rows upwind (from the downwind box) and one
    /// downwind (from the upwind box) of every plane but the last.
    #[test]
    fn the_halo_is_the_stencils() {
        let boxes = Boxes::new([16, 16, 16], [1, 1, 2]).unwrap();
        let sent = |u: DVec3, model| box_schedule(&boxes, u, model).unwrap().values;
        let along_z = DVec3::new(0.2, -0.3, 1.0);
        assert_eq!(sent(along_z, Model::Paper), [256, 0]);
        assert_eq!(sent(-along_z, Model::Paper), [0, 256]);
        assert_eq!(sent(along_z, Model::Characteristic), [256, 0]);
        // Along x, z falling: rank 1 (z 8..16) is upwind along z.
        let along_x = DVec3::new(1.0, 0.3, -0.2);
        assert_eq!(sent(along_x, Model::Characteristic), [16 * 15, 2 * 16 * 15]);
        assert_eq!(
            sent(DVec3::new(1.0, 0.3, 0.2), Model::Characteristic),
            [2 * 16 * 15, 16 * 15]
        );
        let alone = box_schedule(
            &Boxes::new([16, 16, 16], [1, 1, 1]).unwrap(),
            along_z,
            Model::Paper,
        );
        assert_eq!(alone.unwrap().messages, [0]);
    }

    /// In lock step a rank derives its own part of the schedule: its tasks (steps and
    /// waits), the ranks it reads from and that read from it, and their tasks, all as in
    /// the whole schedule, and nobody else's tasks. Boxes one and two cells thin, where
    /// the stencil reaches past the next box, included.
    #[test]
    fn a_rank_in_lock_step_derives_only_its_part() {
        let z = DVec3::new(0.3, -0.2, 1.0).normalize();
        for boxes in [
            Boxes::new([40, 36, 30], [3, 4, 1]).unwrap(),
            Boxes::from_cuts(
                [27, 19, 23],
                [vec![0, 27], vec![0, 17, 18, 19], vec![0, 23]],
            )
            .unwrap(),
            Boxes::from_cuts(
                [24, 12, 9],
                [vec![0, 8, 16, 24], vec![0, 2, 12], vec![0, 9]],
            )
            .unwrap(),
        ] {
            let whole = Plan::new(&boxes, z, Model::Characteristic).unwrap();
            assert!(whole.frame.plane_major);
            // A rank the boxes do not have is a typed error, not a panic.
            assert!(matches!(
                rank_plan_tasks(&boxes, z, Model::Characteristic, boxes.ranks()),
                Err(DecompositionError::BoxGrid { .. })
            ));
            let total: usize = whole.tasks.iter().map(Vec::len).sum();
            for rank in 0..boxes.ranks() {
                let part = Plan::for_rank(&boxes, z, Model::Characteristic, rank).unwrap();
                assert_eq!(part.steps, whole.steps);
                assert_eq!(part.tasks[rank], whole.tasks[rank], "{boxes:?} rank {rank}");
                assert_eq!(part.fed_by[rank], whole.fed_by[rank]);
                assert_eq!(part.feeds[rank], whole.feeds[rank]);
                for q in 0..boxes.ranks() {
                    if part.fed_by[rank].contains(&q) {
                        assert_eq!(
                            part.tasks[q]
                                .iter()
                                .map(|t| (t.plane, t.rows.clone(), t.step))
                                .collect::<Vec<_>>(),
                            whole.tasks[q]
                                .iter()
                                .map(|t| (t.plane, t.rows.clone(), t.step))
                                .collect::<Vec<_>>()
                        );
                    } else if q != rank {
                        assert!(part.tasks[q].is_empty());
                    }
                }
                let derived: usize = part.tasks.iter().map(Vec::len).sum();
                let needed: usize = std::iter::once(rank)
                    .chain(part.fed_by[rank].iter().copied())
                    .map(|q| whole.tasks[q].len())
                    .sum();
                assert_eq!(derived, needed, "{boxes:?} rank {rank}");
                assert_eq!(
                    rank_plan_tasks(&boxes, z, Model::Characteristic, rank).unwrap(),
                    derived
                );
                // On the 3 × 4 grid a rank reads from its eight neighbours at most.
                if boxes.ranks() == 12 {
                    assert!(
                        derived < total,
                        "{boxes:?} rank {rank}: {derived} of {total}"
                    );
                }
            }
        }
    }

    /// Chunks widen to keep the schedule under its bound, and the schedule stays whole
    /// (every task gets a step) however wide they get.
    #[test]
    fn chunks_widen_to_bound_the_tasks() {
        let boxes = Boxes::new([48, 40, 36], [2, 2, 3]).unwrap();
        for (u, model) in [
            (DVec3::new(0.3, -0.2, 1.0), Model::Characteristic),
            (DVec3::new(-1.0, 0.4, 0.2), Model::Characteristic),
            (DVec3::new(0.3, -0.2, 1.0), Model::Paper),
        ] {
            let u = u.normalize();
            let free = Plan::new(&boxes, u, model).unwrap();
            let total = |plan: &Plan| plan.tasks.iter().map(Vec::len).sum::<usize>();
            for limit in [2000, 500, 10] {
                let bounded = Plan::with_limit(&boxes, u, model, limit, None).unwrap();
                assert!(bounded.frame.rows >= free.frame.rows);
                // A plane of each box is the fewest tasks there can be.
                let floor = boxes.dims()[bounded.frame.axes[0]]
                    * boxes.grid()[bounded.frame.axes[1]]
                    * boxes.grid()[bounded.frame.axes[2]];
                assert!(
                    total(&bounded) <= limit.max(floor) + floor,
                    "{model:?} {u}, {limit}: {} tasks",
                    total(&bounded)
                );
                assert!(bounded.steps > 0 && bounded.steps <= total(&bounded));
            }
        }
    }
}
