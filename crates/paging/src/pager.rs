//! The pager: a fixed pool of brick slots under a byte budget, a page table, and the
//! resident / dirty / referenced bits of Bernabei's chapter 5.
//!
//! A brick is *pinned* while a [`ReadPin`] or [`WritePin`] of it lives: the pin owns a
//! reference to the slot and holds its lock, so the slot cannot be chosen for eviction (a
//! slot is evictable exactly when the pool holds the only reference to it) and its data
//! cannot change under a reader. All bookkeeping — the table, the bits, the choice of a
//! victim and the I/O of a miss — happens under one mutex: a miss is serialised, a hit
//! costs one short critical section, and no reader can observe a brick half loaded or a
//! victim half written back. A write-back that fails leaves the victim resident and dirty
//! (the error is returned; nothing is lost). [`Pager::write_back`] is the one exception:
//! it writes resident bricks out with the I/O outside the lock (holding a reference and
//! the slot's read lock instead), so that a helper can clean bricks behind a sweep.
//!
//! Eviction ([`Eviction`]): `Lru` evicts the unpinned slot used longest ago (a counter
//! stamped at every pin); `Nru` is the clock algorithm (a hand sweeps the slots, clearing
//! referenced bits, and takes the first unpinned slot whose bit is already clear), which
//! needs no per-pin timestamp ordering and is what Bernabei uses.
//!
//! **Deadlock rule.** A thread that holds a [`WritePin`] of a brick must not pin that
//! brick again before dropping it (the slot's lock is not re-entrant for writers).

use std::sync::Arc;

use parking_lot::{ArcRwLockReadGuard, ArcRwLockWriteGuard, Mutex, RawRwLock, RwLock};
use serde::Serialize;

use crate::error::PagingError;
use crate::store::BrickStore;

/// Which resident brick leaves the pool when a slot is needed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Eviction {
    /// Least recently used.
    #[default]
    Lru,
    /// Not recently used: the clock algorithm over referenced bits.
    Nru,
}

/// What the pager did, for the solve report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct PagerStats {
    /// Pins of resident bricks.
    pub hits: u64,
    /// Pins that had to load (or create) the brick.
    pub misses: u64,
    /// Bricks loaded ahead of use by [`Pager::prefetch`].
    pub prefetched: u64,
    /// Bricks that left the pool.
    pub evictions: u64,
    /// Evicted or flushed bricks that were dirty and written back.
    pub write_backs: u64,
    /// Bytes read from the backing store.
    pub bytes_read: u64,
    /// Bytes written to the backing store.
    pub bytes_written: u64,
    /// Slots in the pool.
    pub slots: u64,
}

impl PagerStats {
    /// What happened between `before` (an earlier reading of the same pager) and these
    /// counters; the slot count is this reading's.
    pub fn since(&self, before: &PagerStats) -> PagerStats {
        PagerStats {
            hits: self.hits - before.hits,
            misses: self.misses - before.misses,
            prefetched: self.prefetched - before.prefetched,
            evictions: self.evictions - before.evictions,
            write_backs: self.write_backs - before.write_backs,
            bytes_read: self.bytes_read - before.bytes_read,
            bytes_written: self.bytes_written - before.bytes_written,
            slots: self.slots,
        }
    }

    /// The counters of two pagers (or two runs) together; the larger pool's slot count.
    pub fn plus(&self, other: &PagerStats) -> PagerStats {
        PagerStats {
            hits: self.hits + other.hits,
            misses: self.misses + other.misses,
            prefetched: self.prefetched + other.prefetched,
            evictions: self.evictions + other.evictions,
            write_backs: self.write_backs + other.write_backs,
            bytes_read: self.bytes_read + other.bytes_read,
            bytes_written: self.bytes_written + other.bytes_written,
            slots: self.slots.max(other.slots),
        }
    }

    /// Hits over pins (1 when nothing was pinned).
    pub fn hit_rate(&self) -> f64 {
        let pins = self.hits + self.misses;
        if pins == 0 {
            1.0
        } else {
            self.hits as f64 / pins as f64
        }
    }
}

/// What a brick holds: plain numbers that are their bytes (f32 fields; f64 where a
/// solver's state needs it, e.g. iterates whose stopping test sits below f32 rounding).
pub trait Element: bytemuck::Pod + Send + Sync + std::fmt::Debug {}
impl Element for f32 {}
impl Element for f64 {}

/// Options of a [`Pager`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PagerOptions<T = f32> {
    /// Bytes the pool's slots may take.
    pub budget_bytes: u64,
    /// The eviction policy.
    pub eviction: Eviction,
    /// The value of a brick that was never written.
    pub fill: T,
}

type Slot<T> = Arc<RwLock<Vec<T>>>;

/// Where a brick is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Entry {
    /// Never written: every value is the fill.
    Fresh,
    /// In the backing store.
    Stored,
    /// In this slot of the pool.
    Resident(u32),
}

#[derive(Debug, Clone, Copy)]
struct SlotMeta {
    brick: usize,
    /// The brick has a copy in the store (so a clean eviction leaves it `Stored`).
    stored: bool,
    dirty: bool,
    referenced: bool,
    last_use: u64,
}

#[derive(Debug)]
struct State<T> {
    table: Vec<Entry>,
    slots: Vec<Slot<T>>,
    meta: Vec<Option<SlotMeta>>,
    free: Vec<u32>,
    hand: usize,
    tick: u64,
    stats: PagerStats,
}

/// A fixed pool of brick slots of `T` values (f32 unless said) over a [`BrickStore`]. The
/// element type follows [`PagerOptions::fill`] where nothing else fixes it: write
/// `fill: 0.0f32` for a pager used on its own (a bare `0.0` is an f64).
#[derive(Debug)]
pub struct Pager<T: Element = f32> {
    store: Box<dyn BrickStore>,
    brick_len: usize,
    capacity: usize,
    options: PagerOptions<T>,
    state: Mutex<State<T>>,
}

/// A brick pinned for reading: its values, which stay resident and unchanged while the
/// pin lives.
pub struct ReadPin<T = f32>(ArcRwLockReadGuard<RawRwLock, Vec<T>>);

/// A brick pinned for writing (marked dirty): written back when it leaves the pool.
pub struct WritePin<T = f32>(ArcRwLockWriteGuard<RawRwLock, Vec<T>>);

impl<T> std::ops::Deref for ReadPin<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        &self.0
    }
}

impl<T> std::ops::Deref for WritePin<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        &self.0
    }
}

impl<T> std::ops::DerefMut for WritePin<T> {
    fn deref_mut(&mut self) -> &mut [T] {
        &mut self.0
    }
}

impl<T> std::fmt::Debug for ReadPin<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ReadPin({} values)", self.0.len())
    }
}

impl<T> std::fmt::Debug for WritePin<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "WritePin({} values)", self.0.len())
    }
}

/// How a brick is pinned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Access {
    Read,
    Write,
    /// Written whole: its old values are not loaded.
    Overwrite,
}

/// Bytes of bookkeeping per brick of a pager's table (besides the pool).
const TABLE_BYTES_PER_BRICK: u64 = std::mem::size_of::<Entry>() as u64;

impl<T: Element> Pager<T> {
    /// Bytes of bookkeeping per brick of the table (besides the pool).
    pub const TABLE_BYTES_PER_BRICK: u64 = TABLE_BYTES_PER_BRICK;

    /// Bytes per value.
    const VALUE_BYTES: u64 = std::mem::size_of::<T>() as u64;

    /// A pager of `bricks` bricks of `brick_len` values over `store`, whose pool holds
    /// `options.budget_bytes / (brick_len · size of T)` slots. Fails with
    /// [`PagingError::BudgetTooSmall`] unless the pool holds `min_slots` bricks (the working
    /// set of one step of its user), before anything is allocated.
    pub fn new(
        store: Box<dyn BrickStore>,
        bricks: usize,
        brick_len: usize,
        min_slots: usize,
        options: PagerOptions<T>,
    ) -> Result<Self, PagingError> {
        let brick_bytes = brick_len.max(1) as u64 * Self::VALUE_BYTES;
        let capacity = (options.budget_bytes / brick_bytes).min(u32::MAX as u64 - 1) as usize;
        if capacity < min_slots.max(1) {
            return Err(PagingError::BudgetTooSmall {
                budget: options.budget_bytes,
                needed: min_slots.max(1) as u64 * brick_bytes,
                what: format!(
                    "a working set of {} bricks of {brick_bytes} bytes",
                    min_slots.max(1)
                ),
            });
        }
        Ok(Self {
            store,
            brick_len,
            capacity,
            options,
            state: Mutex::new(State {
                table: vec![Entry::Fresh; bricks],
                slots: Vec::new(),
                meta: Vec::new(),
                free: Vec::new(),
                hand: 0,
                tick: 0,
                stats: PagerStats {
                    slots: capacity as u64,
                    ..PagerStats::default()
                },
            }),
        })
    }

    /// Values per brick.
    pub fn brick_len(&self) -> usize {
        self.brick_len
    }

    /// Slots in the pool.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Bricks the table covers.
    pub fn brick_count(&self) -> usize {
        self.state.lock().table.len()
    }

    /// Adds `count` bricks (all fresh) to the table and returns the number of the first:
    /// several fields share one pool and one budget.
    pub fn add_bricks(&self, count: usize) -> usize {
        let mut state = self.state.lock();
        let first = state.table.len();
        state.table.resize(first + count, Entry::Fresh);
        first
    }

    /// The options.
    pub fn options(&self) -> &PagerOptions<T> {
        &self.options
    }

    /// The counters so far.
    pub fn stats(&self) -> PagerStats {
        self.state.lock().stats
    }

    /// Whether `brick` is in the pool now.
    pub fn is_resident(&self, brick: usize) -> bool {
        matches!(self.state.lock().table.get(brick), Some(Entry::Resident(_)))
    }

    /// Whether `brick` was never written (or was discarded): it reads as the fill.
    pub fn is_fresh(&self, brick: usize) -> bool {
        matches!(self.state.lock().table.get(brick), Some(Entry::Fresh))
    }

    /// Forgets `brick`'s values: it reads as the fill again, its slot (if resident) is
    /// freed without a write-back, and its old copy in the store is never read again.
    /// Scratch bricks (a batch's tallies, once folded) are recycled this way. Fails with
    /// [`PagingError::Pinned`] while the brick is pinned.
    pub fn discard(&self, brick: usize) -> Result<(), PagingError> {
        let mut state = self.state.lock();
        self.check(&state, brick)?;
        if let Entry::Resident(s) = state.table[brick] {
            let s = s as usize;
            if Arc::strong_count(&state.slots[s]) > 1 {
                return Err(PagingError::Pinned { brick });
            }
            state.meta[s] = None;
            state.free.push(s as u32);
        }
        state.table[brick] = Entry::Fresh;
        Ok(())
    }

    /// Pins `brick` for reading.
    pub fn read(&self, brick: usize) -> Result<ReadPin<T>, PagingError> {
        let slot = self.pin(brick, Access::Read)?;
        Ok(ReadPin(slot.read_arc()))
    }

    /// Pins `brick` for writing (it is marked dirty).
    pub fn write(&self, brick: usize) -> Result<WritePin<T>, PagingError> {
        let slot = self.pin(brick, Access::Write)?;
        Ok(WritePin(slot.write_arc()))
    }

    /// Pins `brick` for writing without loading it: the caller writes every value (the
    /// pin's values are unspecified until then).
    pub fn overwrite(&self, brick: usize) -> Result<WritePin<T>, PagingError> {
        let slot = self.pin(brick, Access::Overwrite)?;
        Ok(WritePin(slot.write_arc()))
    }

    /// Writes `values` as brick `brick` straight to the store, without a slot (building a
    /// field larger than the pool). A resident copy is replaced in place.
    pub fn store_brick(&self, brick: usize, values: &[T]) -> Result<(), PagingError> {
        if values.len() != self.brick_len {
            return Err(PagingError::Shape(format!(
                "store_brick: {} values for bricks of {}",
                values.len(),
                self.brick_len
            )));
        }
        if let Ok(mut pin) = self.resident_write(brick) {
            pin.copy_from_slice(values);
            return Ok(());
        }
        let mut state = self.state.lock();
        self.check(&state, brick)?;
        self.store_write(&mut state.stats, brick, values)?;
        state.table[brick] = Entry::Stored;
        Ok(())
    }

    /// A write pin of `brick` if it is resident (no load), else an error.
    fn resident_write(&self, brick: usize) -> Result<WritePin<T>, ()> {
        let slot = {
            let mut state = self.state.lock();
            match state.table.get(brick) {
                Some(Entry::Resident(s)) => {
                    let s = *s as usize;
                    state.tick += 1;
                    let tick = state.tick;
                    if let Some(m) = state.meta[s].as_mut() {
                        m.dirty = true;
                        m.referenced = true;
                        m.last_use = tick;
                    }
                    state.slots[s].clone()
                }
                _ => return Err(()),
            }
        };
        Ok(WritePin(slot.write_arc()))
    }

    /// Loads the bricks of `bricks` that are not resident, in order, while free or
    /// evictable slots remain, stopping at the first that would need a pinned slot. Loads
    /// count as `prefetched`, not as misses. Call it with the next bricks of the streaming
    /// order (from another thread, to overlap the reads with work).
    pub fn prefetch(&self, bricks: impl IntoIterator<Item = usize>) -> Result<(), PagingError> {
        for brick in bricks {
            let mut state = self.state.lock();
            self.check(&state, brick)?;
            if matches!(state.table[brick], Entry::Resident(_)) {
                continue;
            }
            match self.load(&mut state, brick, Access::Read) {
                Ok(_) => {
                    state.stats.prefetched += 1;
                    // A prefetched brick has not been used: first in line for the clock.
                    if let Entry::Resident(s) = state.table[brick]
                        && let Some(m) = state.meta[s as usize].as_mut()
                    {
                        m.referenced = false;
                    }
                }
                Err(PagingError::PoolExhausted { .. }) => return Ok(()),
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// Writes the dirty resident bricks among `bricks` back to the store, leaving them
    /// resident and clean, with the I/O outside the pager's lock: a helper thread can
    /// write behind a sweep while other threads pin and work, so that evicting these
    /// bricks later costs no I/O. A brick pinned for writing now is skipped (it is still
    /// being changed); a brick pinned for writing while it is written back stays dirty.
    pub fn write_back(&self, bricks: impl IntoIterator<Item = usize>) -> Result<(), PagingError> {
        for brick in bricks {
            let (s, slot) = {
                let state = self.state.lock();
                self.check(&state, brick)?;
                let Entry::Resident(s) = state.table[brick] else {
                    continue;
                };
                let s = s as usize;
                if !state.meta[s].is_some_and(|m| m.dirty) {
                    continue;
                }
                (s, state.slots[s].clone())
            };
            // Our reference keeps the slot from being evicted; the read lock keeps its
            // values from changing while they are written.
            let Some(data) = slot.try_read() else {
                continue;
            };
            let written = self.write_to_store(brick, &data)?;
            let mut state = self.state.lock();
            state.stats.bytes_written += written;
            state.stats.write_backs += 1;
            // Clean only if no one else holds the slot: a writer that pinned it meanwhile
            // (marked dirty, waiting for our read lock) keeps it dirty.
            if Arc::strong_count(&slot) == 2
                && let Some(m) = state.meta[s].as_mut()
                && m.brick == brick
            {
                m.dirty = false;
                m.stored = true;
            }
            drop(data);
        }
        Ok(())
    }

    /// Writes every dirty resident brick back (they stay resident, now clean).
    pub fn flush(&self) -> Result<(), PagingError> {
        let mut state = self.state.lock();
        for s in 0..state.slots.len() {
            let Some(meta) = state.meta[s] else { continue };
            if !meta.dirty {
                continue;
            }
            let slot = state.slots[s].clone();
            // A brick being written now is skipped: its pin is still making it dirty.
            let Some(data) = slot.try_read() else {
                continue;
            };
            self.store_write(&mut state.stats, meta.brick, &data)?;
            drop(data);
            if let Some(m) = state.meta[s].as_mut() {
                m.dirty = false;
                m.stored = true;
            }
            state.stats.write_backs += 1;
        }
        Ok(())
    }

    fn check(&self, state: &State<T>, brick: usize) -> Result<(), PagingError> {
        if brick < state.table.len() {
            Ok(())
        } else {
            Err(PagingError::NoSuchBrick {
                brick,
                count: state.table.len(),
            })
        }
    }

    /// The slot of `brick`, resident after this call and referenced by the returned Arc
    /// (so not evictable until the caller's pin is dropped).
    fn pin(&self, brick: usize, access: Access) -> Result<Slot<T>, PagingError> {
        let mut state = self.state.lock();
        self.check(&state, brick)?;
        state.tick += 1;
        let tick = state.tick;
        let s = match state.table[brick] {
            Entry::Resident(s) => {
                state.stats.hits += 1;
                s as usize
            }
            _ => {
                state.stats.misses += 1;
                self.load(&mut state, brick, access)?
            }
        };
        if let Some(m) = state.meta[s].as_mut() {
            m.referenced = true;
            m.last_use = tick;
            if access != Access::Read {
                m.dirty = true;
            }
        }
        Ok(state.slots[s].clone())
    }

    /// Puts `brick` (not resident) into a slot: a free one, a new one while the pool is
    /// below its capacity, or the victim of the eviction policy (written back first if
    /// dirty). Under the state lock.
    fn load(
        &self,
        state: &mut State<T>,
        brick: usize,
        access: Access,
    ) -> Result<usize, PagingError> {
        let s = if let Some(s) = state.free.pop() {
            s as usize
        } else if state.slots.len() < self.capacity {
            state.slots.push(Arc::new(RwLock::new(vec![
                self.options.fill;
                self.brick_len
            ])));
            state.meta.push(None);
            state.slots.len() - 1
        } else {
            self.evict(state)?
        };
        let entry = state.table[brick];
        {
            // The slot is unpinned (free or just evicted): its lock is free.
            let slot = state.slots[s].clone();
            let mut data = slot.write();
            match (access, entry) {
                (Access::Overwrite, _) => {}
                (_, Entry::Stored) => {
                    if let Err(source) = self.store.read(brick, bytemuck::cast_slice_mut(&mut data))
                    {
                        drop(data);
                        state.free.push(s as u32);
                        return Err(PagingError::Io {
                            action: "reading",
                            brick,
                            store: self.store.describe(),
                            source,
                        });
                    }
                    state.stats.bytes_read += self.brick_len as u64 * Self::VALUE_BYTES;
                }
                _ => data.fill(self.options.fill),
            }
        }
        state.meta[s] = Some(SlotMeta {
            brick,
            stored: entry == Entry::Stored,
            dirty: false,
            referenced: true,
            last_use: state.tick,
        });
        state.table[brick] = Entry::Resident(s as u32);
        Ok(s)
    }

    /// Frees a slot by the eviction policy; its brick is written back first if dirty.
    fn evict(&self, state: &mut State<T>) -> Result<usize, PagingError> {
        let n = state.slots.len();
        let unpinned = |state: &State<T>, s: usize| Arc::strong_count(&state.slots[s]) == 1;
        let victim = match self.options.eviction {
            Eviction::Lru => (0..n)
                .filter(|&s| unpinned(state, s) && state.meta[s].is_some())
                .min_by_key(|&s| state.meta[s].map_or(u64::MAX, |m| m.last_use)),
            Eviction::Nru => {
                // Two turns of the hand: the first clears referenced bits, the second
                // finds one clear unless every slot is pinned.
                let mut found = None;
                for _ in 0..2 * n {
                    let s = state.hand;
                    state.hand = (state.hand + 1) % n;
                    if !unpinned(state, s) {
                        continue;
                    }
                    if let Some(m) = state.meta[s].as_mut() {
                        if m.referenced {
                            m.referenced = false;
                        } else {
                            found = Some(s);
                            break;
                        }
                    }
                }
                found
            }
        };
        let s = victim.ok_or(PagingError::PoolExhausted { slots: n })?;
        let meta = state.meta[s].expect("a victim holds a brick");
        if meta.dirty {
            let slot = state.slots[s].clone();
            let data = slot.read();
            self.store_write(&mut state.stats, meta.brick, &data)?;
            state.stats.write_backs += 1;
        }
        state.table[meta.brick] = if meta.dirty || meta.stored {
            Entry::Stored
        } else {
            Entry::Fresh
        };
        state.meta[s] = None;
        state.stats.evictions += 1;
        Ok(s)
    }

    fn store_write(
        &self,
        stats: &mut PagerStats,
        brick: usize,
        data: &[T],
    ) -> Result<(), PagingError> {
        stats.bytes_written += self.write_to_store(brick, data)?;
        Ok(())
    }

    /// Writes `data` as brick `brick` to the store (no lock needed: positioned I/O) and
    /// returns the bytes written.
    fn write_to_store(&self, brick: usize, data: &[T]) -> Result<u64, PagingError> {
        self.store
            .write(brick, bytemuck::cast_slice(data))
            .map_err(|source| PagingError::Io {
                action: "writing",
                brick,
                store: self.store.describe(),
                source,
            })?;
        Ok(data.len() as u64 * Self::VALUE_BYTES)
    }
}
