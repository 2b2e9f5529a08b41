//! Fuzz targets, shared by the libFuzzer harness in `fuzz/` (nightly, `cargo fuzz run
//! TARGET`), the stable mutation harness `cargo xtask fuzz`, and the regression corpus that
//! `cargo test` replays (`tests/it/fuzz_regressions.rs`).
//!
//! Each [`Target`] feeds arbitrary bytes to one reader (or to the scene parser and
//! [`Scene::build_within`]) under a small memory budget. A target never panics, never
//! hangs and never returns a grid holding a non-finite value: anything else is a finding.
//! [`seeds`] gives each target small valid inputs to start from.

use std::path::Path;

use lucent_grid::io::{self, Endian, LoadOptions, ScalarType};
use lucent_grid::{Grid, GridGeometry};

use crate::scene::Scene;

/// The memory budget of every fuzzed read and scene build (16 MiB): enough for every seed,
/// small enough that a crafted size is refused rather than allocated. An input may
/// legitimately ask for a grid up to the budget, and filling it is the slowest thing a
/// reader does: at 64 MiB a 10 kB VDB whose tiles span the budget took 0.5 s in release
/// and 7 s under libFuzzer's instrumentation, which libFuzzer reports as a timeout.
pub const FUZZ_BUDGET: u64 = 16 << 20;

/// What a fuzz input is fed to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// Headerless raw: the first four bytes choose the dimensions (1 to 16 each) and the
    /// voxel type, the rest is the payload.
    Raw,
    /// NRRD with an attached payload.
    Nrrd,
    /// MetaImage `.mha` (attached payload).
    Mhd,
    /// Legacy VTK structured points.
    Vtk,
    /// Mitsuba `.vol`.
    Vol,
    /// NumPy `.npy`.
    Npy,
    /// OpenVDB.
    Vdb,
    /// A scene file: TOML parsing, then building the problem within the budget.
    Scene,
}

impl Target {
    /// Every target.
    pub const ALL: [Target; 8] = [
        Target::Raw,
        Target::Nrrd,
        Target::Mhd,
        Target::Vtk,
        Target::Vol,
        Target::Npy,
        Target::Vdb,
        Target::Scene,
    ];

    /// Its name (the `fuzz/` target and corpus folder).
    pub fn name(self) -> &'static str {
        match self {
            Target::Raw => "raw",
            Target::Nrrd => "nrrd",
            Target::Mhd => "mhd",
            Target::Vtk => "vtk",
            Target::Vol => "vol",
            Target::Npy => "npy",
            Target::Vdb => "vdb",
            Target::Scene => "scene",
        }
    }

    /// The target called `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.name() == name)
    }
}

/// What a fuzz input did: read (or built) fine, or refused with this message. A panic or a
/// non-finite value is not an outcome: [`run`] panics on the latter so that every harness
/// sees it as a crash.
pub type Outcome = Result<(), String>;

fn checked(grid: Result<Grid, lucent_grid::GridError>) -> Outcome {
    let grid = grid.map_err(|e| e.to_string())?;
    assert!(
        grid.data().iter().all(|v| v.is_finite()),
        "a reader returned a non-finite voxel"
    );
    Ok(())
}

/// Feeds `bytes` to `target`.
pub fn run(target: Target, bytes: &[u8]) -> Outcome {
    let options = LoadOptions {
        memory_budget: FUZZ_BUDGET,
    };
    let path = Path::new("fuzz-input");
    match target {
        Target::Raw => {
            let (head, payload) = bytes.split_at(bytes.len().min(4));
            let pick = |i: usize| head.get(i).copied().unwrap_or(0);
            let dims = [0, 1, 2].map(|a| usize::from(pick(a) % 16) + 1);
            let scalar = [
                ScalarType::U8,
                ScalarType::I8,
                ScalarType::U16,
                ScalarType::I16,
                ScalarType::U32,
                ScalarType::I32,
                ScalarType::F16,
                ScalarType::F32,
                ScalarType::F64,
            ][usize::from(pick(3) % 9)];
            let mut layout = io::raw::RawLayout::new(dims, scalar);
            if pick(3) >= 128 {
                layout.endian = Endian::Big;
            }
            checked(io::raw::parse(payload, path, &layout, &options))
        }
        Target::Nrrd => checked(io::nrrd::parse(bytes, path, &options)),
        Target::Mhd => checked(io::mhd::parse(bytes, path, &options)),
        Target::Vtk => checked(io::vtk::parse(bytes, path, &options)),
        Target::Vol => {
            let grids = io::mitsuba::parse(bytes, path, &options).map_err(|e| e.to_string())?;
            for g in grids {
                checked(Ok(g))?;
            }
            Ok(())
        }
        Target::Npy => checked(io::npy::parse(bytes, path, &options)),
        Target::Vdb => {
            let volume = io::vdb::parse(bytes, path, None, &options).map_err(|e| e.to_string())?;
            checked(Ok(volume.grid))
        }
        Target::Scene => {
            let text = String::from_utf8_lossy(bytes);
            let scene = Scene::parse(&text, path).map_err(|e| e.to_string())?;
            // Relative volume paths point nowhere; `data:` ones at the shared volumes.
            let built = scene
                .build_within(Path::new("/nonexistent"), FUZZ_BUDGET)
                .map_err(|e| e.to_string())?;
            assert!(
                built.volume.data().iter().all(|v| v.is_finite()),
                "a scene built a non-finite volume"
            );
            // Every solver's admission check runs on whatever was built.
            for entry in crate::registry().entries() {
                if let Ok(solver) = (entry.build)(&scene.solver.params) {
                    let _ = solver.admits(&built.problem);
                }
            }
            Ok(())
        }
    }
}

/// A small valid grid for the seeds: a blob on 6 × 5 × 4 cells.
fn seed_grid() -> Grid {
    let geometry = GridGeometry::new(
        [6, 5, 4],
        glam::DVec3::new(0.5, 0.25, 1.0),
        glam::DVec3::new(-1.0, 0.0, 2.0),
    )
    .expect("a valid geometry");
    Grid::from_fn(geometry, |x| (1.0 - 0.1 * x.length_squared()) as f32)
}

/// Small valid inputs of `target`, written by lucent's own writers (and, for OpenVDB, which
/// lucent does not write, by [`minimal_vdb`]); scenes are the example scenes.
pub fn seeds(target: Target) -> Vec<Vec<u8>> {
    let Ok(dir) = tempfile_dir() else {
        return Vec::new();
    };
    let grid = seed_grid();
    // Integer samples for the integer voxel types (writers refuse a lossy conversion).
    let counts = grid.map(|v| (10.0 * v).abs().round());
    let file = |name: &str, write: &dyn Fn(&Path) -> Result<(), lucent_grid::GridError>| {
        let path = dir.join(name);
        write(&path).ok()?;
        std::fs::read(&path).ok()
    };
    let seeds: Vec<Option<Vec<u8>>> = match target {
        Target::Raw => vec![Some([vec![5, 4, 3, 7], vec![0u8; 6 * 5 * 4 * 4]].concat())],
        Target::Nrrd => vec![
            file("a.nrrd", &|p| {
                io::nrrd::write(p, &grid, ScalarType::F32, io::nrrd::Encoding::Raw)
            }),
            file("b.nrrd", &|p| {
                io::nrrd::write(p, &counts, ScalarType::U16, io::nrrd::Encoding::Gzip)
            }),
        ],
        Target::Mhd => vec![file("a.mha", &|p| {
            io::mhd::write(p, &grid, ScalarType::F32)
        })],
        Target::Vtk => vec![file("a.vtk", &|p| {
            io::vtk::write(p, &grid, ScalarType::F32)
        })],
        Target::Vol => vec![file("a.vol", &|p| io::mitsuba::write(p, &[&grid]))],
        Target::Npy => vec![
            file("a.npy", &|p| io::npy::write(p, &grid, ScalarType::F32)),
            file("b.npy", &|p| io::npy::write(p, &counts, ScalarType::U8)),
        ],
        Target::Vdb => vec![Some(minimal_vdb())],
        Target::Scene => {
            let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes");
            let mut texts: Vec<Option<Vec<u8>>> = std::fs::read_dir(&folder)
                .map(|entries| {
                    entries
                        .filter_map(|e| e.ok())
                        .map(|e| e.path())
                        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
                        .map(|p| std::fs::read(p).ok())
                        .collect()
                })
                .unwrap_or_default();
            texts.push(Some(crate::scene::DEFAULT_SCENE.as_bytes().to_vec()));
            // At 8³ cells a build takes about a millisecond; mutations reach other sizes.
            texts
                .into_iter()
                .map(|t| t.map(|t| small_resolution(&String::from_utf8_lossy(&t)).into_bytes()))
                .collect()
        }
    };
    let _ = std::fs::remove_dir_all(&dir);
    seeds.into_iter().flatten().collect()
}

/// `text` with every `resolution = [...]` line set to 8 cells per axis.
fn small_resolution(text: &str) -> String {
    text.lines()
        .map(|line| {
            if line.trim_start().starts_with("resolution") {
                "resolution = [8, 8, 8]".to_owned()
            } else {
                line.to_owned()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn tempfile_dir() -> std::io::Result<std::path::PathBuf> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "lucent-fuzz-seeds-{}-{}",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir)?;
    Ok(dir)
}

/// A minimal OpenVDB file (version 224, one float grid `density`, one root child, one
/// internal node of each level and one leaf with its first 64 voxels active), about
/// 10 kB: the seed of the VDB target, where the real `smoke.vdb` (2.5 MB) would make every
/// execution slow.
pub fn minimal_vdb() -> Vec<u8> {
    fn string(b: &mut Vec<u8>, s: &str) {
        b.extend_from_slice(&(s.len() as u32).to_le_bytes());
        b.extend_from_slice(s.as_bytes());
    }
    let mut b = Vec::new();
    b.extend_from_slice(&0x5644_4220u64.to_le_bytes());
    b.extend_from_slice(&224u32.to_le_bytes());
    b.extend_from_slice(&10u32.to_le_bytes());
    b.extend_from_slice(&0u32.to_le_bytes());
    b.push(1); // grid offsets
    b.extend_from_slice(&[b'0'; 36]); // uuid
    b.extend_from_slice(&0u32.to_le_bytes()); // file metadata
    b.extend_from_slice(&1u32.to_le_bytes()); // grid count
    string(&mut b, "density");
    string(&mut b, "Tree_float_5_4_3");
    string(&mut b, "");
    let offsets_at = b.len();
    b.extend_from_slice(&[0u8; 24]); // grid, block and end positions, patched below
    let grid_pos = b.len() as u64;
    b.extend_from_slice(&2u32.to_le_bytes()); // compression: active mask only
    b.extend_from_slice(&0u32.to_le_bytes()); // grid metadata
    string(&mut b, "UniformScaleMap");
    for v in [0.5f64; 15] {
        b.extend_from_slice(&v.to_le_bytes()); // scale, then four derived vectors
    }
    b.extend_from_slice(&1u32.to_le_bytes()); // buffer count
    b.extend_from_slice(&0f32.to_le_bytes()); // background
    b.extend_from_slice(&0u32.to_le_bytes()); // root tiles
    b.extend_from_slice(&1u32.to_le_bytes()); // root children
    b.extend_from_slice(&[0u8; 12]); // the child's origin
    let mask = |bits: usize, first: bool| {
        let mut m = vec![0u8; bits / 8];
        if first {
            m[0] = 1;
        }
        m
    };
    b.extend_from_slice(&mask(32768, true)); // node5 child mask
    b.extend_from_slice(&mask(32768, false)); // value mask
    b.push(0); // node metadata: no active values stored
    b.extend_from_slice(&mask(4096, true)); // node4 child mask
    b.extend_from_slice(&mask(4096, false));
    b.push(0);
    b.extend_from_slice(&mask(512, false)); // the leaf's topology mask
    let block_pos = b.len() as u64;
    let mut leaf = vec![0u8; 64];
    leaf[..8].fill(0xFF); // the first 64 voxels active
    b.extend_from_slice(&leaf);
    b.push(0);
    for i in 0..64 {
        b.extend_from_slice(&(0.25 + i as f32 / 64.0).to_le_bytes());
    }
    let end_pos = b.len() as u64;
    for (i, v) in [grid_pos, block_pos, end_pos].into_iter().enumerate() {
        b[offsets_at + 8 * i..offsets_at + 8 * i + 8].copy_from_slice(&v.to_le_bytes());
    }
    b
}

/// A small, seeded random stream (xorshift64*): the harness must not depend on the
/// platform's randomness, so that a run can be repeated from its seed.
#[derive(Debug, Clone)]
pub struct Stream(u64);

impl Stream {
    /// A stream from `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    /// The next 64 random bits.
    pub fn bits(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// A number in 0..n (0 when n is 0).
    pub fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.bits() % n as u64) as usize
        }
    }
}

/// Values that break size checks and parsers more often than random bytes do.
const INTERESTING: [&[u8]; 12] = [
    &[0],
    &[0xFF],
    &[0x7F],
    &[0x80],
    &[0xFF, 0xFF, 0xFF, 0xFF],
    &[0x00, 0x00, 0x00, 0x80],
    &[0xFF, 0xFF, 0xFF, 0x7F],
    &[0, 0, 0xC0, 0x7F], // f32 NaN
    &[0, 0, 0x80, 0x7F], // f32 +inf
    &[0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF],
    &[0, 0, 0, 0, 0, 0, 0xF8, 0x7F], // f64 NaN
    &[1, 0, 0, 0],
];

/// Text that breaks number parsing in headers and scenes.
const NUMBERS: [&str; 12] = [
    "0",
    "-1",
    "nan",
    "inf",
    "-inf",
    "1e300",
    "1e-300",
    "4294967296",
    "9223372036854775808",
    "18446744073709551615",
    "65536",
    "-0",
];

/// One random edit of `input`, drawing on `others` for splices: bit flips, byte and
/// interesting-value overwrites, inserts, deletions, duplications, truncation, splices, and
/// (for text) a number replaced by `nan`, `inf`, `1e300`, a 64-bit limit and the like.
pub fn mutate(input: &[u8], others: &[Vec<u8>], rng: &mut Stream) -> Vec<u8> {
    let mut b = input.to_vec();
    let edits = 1 + rng.below(4);
    for _ in 0..edits {
        let len = b.len();
        match rng.below(10) {
            0 if len > 0 => {
                let i = rng.below(len);
                b[i] ^= 1 << rng.below(8);
            }
            1 if len > 0 => {
                let i = rng.below(len);
                b[i] = rng.bits() as u8;
            }
            2 if len > 0 => {
                let v = INTERESTING[rng.below(INTERESTING.len())];
                let i = rng.below(len);
                for (k, byte) in v.iter().enumerate() {
                    if let Some(slot) = b.get_mut(i + k) {
                        *slot = *byte;
                    }
                }
            }
            3 => {
                let i = rng.below(len + 1);
                let n = 1 + rng.below(16);
                let bytes: Vec<u8> = (0..n).map(|_| rng.bits() as u8).collect();
                b.splice(i..i, bytes);
            }
            4 if len > 0 => {
                let i = rng.below(len);
                let n = 1 + rng.below((len - i).min(64));
                b.drain(i..i + n);
            }
            5 if len > 0 => {
                let i = rng.below(len);
                let n = 1 + rng.below((len - i).min(64));
                let copy = b[i..i + n].to_vec();
                let at = rng.below(len + 1);
                b.splice(at..at, copy);
            }
            6 if len > 0 => b.truncate(rng.below(len)),
            7 if !others.is_empty() => {
                let other = &others[rng.below(others.len())];
                let cut = rng.below(len + 1);
                let from = rng.below(other.len() + 1);
                b.truncate(cut);
                b.extend_from_slice(&other[from..]);
            }
            _ => {
                // A number in text replaced (headers and scenes are text).
                let digits: Vec<usize> = (0..len).filter(|&i| b[i].is_ascii_digit()).collect();
                if digits.is_empty() {
                    continue;
                }
                let start = digits[rng.below(digits.len())];
                let mut end = start;
                while end < len && (b[end].is_ascii_digit() || b[end] == b'.') {
                    end += 1;
                }
                let number = NUMBERS[rng.below(NUMBERS.len())].as_bytes().to_vec();
                b.splice(start..end, number);
            }
        }
    }
    b
}

/// What a [`campaign`] found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Findings {
    /// Inputs run.
    pub executions: u64,
    /// Inputs read or built fine.
    pub accepted: u64,
    /// Distinct outcomes seen (a proxy for the paths reached).
    pub distinct_outcomes: usize,
    /// Inputs that panicked (or produced a non-finite value), as (input, message).
    pub crashes: Vec<(Vec<u8>, String)>,
    /// Inputs that took longer than a second, as (input, seconds).
    pub slow: Vec<(Vec<u8>, f64)>,
    /// Wall time (s).
    pub seconds: f64,
}

/// Runs `executions` mutated inputs of `target`, starting from its [`seeds`] (and any
/// `extra` inputs), keeping each input that gave an outcome not seen before as a parent for
/// further mutation. Panics are caught and recorded with their input.
pub fn campaign(target: Target, executions: u64, seed: u64, extra: &[Vec<u8>]) -> Findings {
    let started = std::time::Instant::now();
    let mut corpus = seeds(target);
    corpus.extend_from_slice(extra);
    if corpus.is_empty() {
        corpus.push(Vec::new());
    }
    let mut seen = std::collections::HashSet::new();
    let mut findings = Findings::default();
    let mut rng = Stream::new(seed);
    let quiet = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    for _ in 0..executions {
        let parent = &corpus[rng.below(corpus.len())];
        let input = mutate(parent, &corpus, &mut rng);
        let t = std::time::Instant::now();
        let outcome = std::panic::catch_unwind(|| run(target, &input));
        let seconds = t.elapsed().as_secs_f64();
        findings.executions += 1;
        if seconds > 1.0 {
            findings.slow.push((input.clone(), seconds));
        }
        match outcome {
            Ok(result) => {
                if result.is_ok() {
                    findings.accepted += 1;
                }
                // The outcome's message without the numbers in it: a new kind of refusal
                // (or acceptance) marks a new path.
                let key: String = match &result {
                    Ok(()) => "ok".into(),
                    Err(e) => e.chars().filter(|c| !c.is_ascii_digit()).collect(),
                };
                if seen.insert(key) && corpus.len() < 4096 && input.len() < 1 << 20 {
                    corpus.push(input);
                }
            }
            Err(panic) => {
                let message = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| (*s).to_owned()))
                    .unwrap_or_default();
                findings.crashes.push((input, message));
            }
        }
    }
    std::panic::set_hook(quiet);
    findings.distinct_outcomes = seen.len();
    findings.seconds = started.elapsed().as_secs_f64();
    findings
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A short campaign per target finds nothing (the full runs are `cargo xtask fuzz`).
    #[test]
    fn a_short_campaign_finds_nothing() {
        for target in Target::ALL {
            let runs = if target == Target::Scene { 30 } else { 300 };
            let findings = campaign(target, runs, 7, &[]);
            assert_eq!(findings.executions, runs);
            assert!(
                findings.crashes.is_empty(),
                "{target:?}: {:?}",
                findings.crashes.iter().map(|c| &c.1).collect::<Vec<_>>()
            );
            assert!(
                findings.distinct_outcomes > 1,
                "{target:?} never left its seeds"
            );
        }
    }

    /// Every target's seeds are valid inputs: a mutation loop starts from something the
    /// reader takes, not from the first error.
    #[test]
    fn every_seed_is_read() {
        for target in Target::ALL {
            let seeds = seeds(target);
            assert!(!seeds.is_empty(), "{target:?} has no seeds");
            let expected = match target {
                Target::Nrrd | Target::Npy => 2,
                _ => 1,
            };
            assert!(seeds.len() >= expected, "{target:?}: {} seeds", seeds.len());
            for seed in &seeds {
                if target == Target::Scene {
                    // Example scenes may point at shared data that is not here.
                    let _ = run(target, seed);
                } else {
                    run(target, seed).unwrap_or_else(|e| panic!("{target:?}: {e}"));
                }
            }
        }
    }
}
