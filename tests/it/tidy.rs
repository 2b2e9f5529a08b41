//! Checks of the repository itself (rust-analyzer's "tidy" tests): the conventions that
//! keep lucent navigable are enforced, not hoped for. Run alone with `cargo xtask tidy`.

use std::fs;
use std::path::{Path, PathBuf};

/// The README's test command; `.ci/run` must run exactly this.
const TEST_COMMAND: &str = "cargo test --workspace";
/// The README's main job.
const RUN_COMMAND: &str = "cargo run --release";

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn read(path: impl AsRef<Path>) -> String {
    let path = root().join(path);
    fs::read_to_string(&path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
}

fn crate_dirs() -> Vec<PathBuf> {
    let mut dirs: Vec<PathBuf> = fs::read_dir(root().join("crates"))
        .expect("crates/ exists")
        .map(|e| e.expect("readable entry").path())
        .filter(|p| p.join("Cargo.toml").exists())
        .collect();
    dirs.sort();
    dirs
}

fn package_name(crate_dir: &Path) -> String {
    let manifest = fs::read_to_string(crate_dir.join("Cargo.toml")).expect("manifest");
    manifest
        .lines()
        .find_map(|l| {
            l.strip_prefix("name = \"")
                .and_then(|r| r.strip_suffix('"'))
        })
        .unwrap_or_else(|| panic!("no package name in {}", crate_dir.display()))
        .to_owned()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() && path.file_name().is_some_and(|n| n != "target") {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

#[test]
fn every_crate_starts_with_a_doc_comment_and_has_an_example() {
    for dir in crate_dirs() {
        let lib = fs::read_to_string(dir.join("src/lib.rs")).expect("lib.rs");
        assert!(
            lib.starts_with("//!"),
            "{}: lib.rs must open with a //! doc comment",
            dir.display()
        );
        let mut examples = Vec::new();
        rust_files(&dir.join("examples"), &mut examples);
        // The Python bindings' examples are Python.
        if package_name(&dir) == "lucent-python" {
            examples.extend(
                fs::read_dir(dir.join("examples"))
                    .into_iter()
                    .flatten()
                    .flatten()
                    .map(|e| e.path())
                    .filter(|p| p.extension().is_some_and(|e| e == "py")),
            );
        }
        assert!(
            !examples.is_empty(),
            "{}: every crate has a runnable example of using it alone",
            dir.display()
        );
    }
}

#[test]
fn architecture_lists_every_crate() {
    let architecture = read("ARCHITECTURE.md");
    let readme = read("README.md");
    for dir in crate_dirs() {
        let name = package_name(&dir);
        assert!(
            architecture.contains(&format!("`{name}`")),
            "ARCHITECTURE.md does not describe `{name}`"
        );
        assert!(
            readme.contains(&format!("`{name}`")),
            "README.md's crate map does not list `{name}`"
        );
    }
}

/// Every crate's numerics are optimised in the test profile: one
/// `[profile.dev.package.<name>]` per crate in `crates/`, the directory being the one place
/// the list comes from.
#[test]
fn every_crate_is_optimised_in_tests() {
    let manifest = read("Cargo.toml");
    for dir in crate_dirs() {
        let name = package_name(&dir);
        assert!(
            manifest.contains(&format!("[profile.dev.package.{name}]\nopt-level = 3")),
            "Cargo.toml lacks `[profile.dev.package.{name}]` with opt-level = 3"
        );
    }
}

/// ARCHITECTURE.md's "Adding a solver" checklist, checked for every crate that registers a
/// solver (one that has `src/solver.rs`).
#[test]
fn adding_a_solver_checklist_holds() {
    let architecture = read("ARCHITECTURE.md");
    assert!(
        architecture.contains("## Adding a solver"),
        "ARCHITECTURE.md has its checklist"
    );
    let manifest = read("Cargo.toml");
    let facade = read("src/lib.rs");
    let pareto = read("src/pareto.rs");
    let tolerances = read("examples/scenes/suite/tolerances.toml");
    let mut solver_crates = 0;
    for dir in crate_dirs() {
        let solver = dir.join("src/solver.rs");
        let name = package_name(&dir);
        // lucent-core's solver.rs is the trait itself (its `direct` is the seam's own
        // first solver, registered by `Registry::with_core_solvers`).
        if !solver.exists() || name == "lucent-core" {
            continue;
        }
        solver_crates += 1;
        let folder = dir.file_name().unwrap().to_string_lossy().into_owned();
        let adapter = fs::read_to_string(&solver).unwrap();
        let params = fs::read_to_string(dir.join("src/params.rs"))
            .unwrap_or_else(|_| panic!("{name}: its parameters go in src/params.rs"));
        assert!(
            params.contains("impl SolverParams for") && params.contains("deny_unknown_fields"),
            "{name}: params.rs holds typed SolverParams with deny_unknown_fields"
        );
        assert!(
            adapter.contains("impl Solver for") && adapter.contains("param_docs::<"),
            "{name}: solver.rs implements Solver and its entries list their parameters"
        );
        assert!(
            adapter.contains("driver::solve_per_channel") || adapter.contains("driver::run"),
            "{name}: solves go through lucent_core::driver"
        );
        let crate_manifest = fs::read_to_string(dir.join("Cargo.toml")).unwrap();
        assert!(
            crate_manifest.contains("lucent-core") && crate_manifest.contains("serde"),
            "{name}: depends on lucent-core and serde"
        );
        let module = name.replace('-', "_");
        assert!(
            manifest.contains(&format!("{name}.workspace = true"))
                && manifest.contains(&format!("{name} = {{ path = \"crates/{folder}\"")),
            "{name}: a workspace dependency of the root package"
        );
        assert!(
            facade.contains(&format!("{module}::")),
            "{name}: src/lib.rs registers its entries"
        );
        assert!(
            architecture.contains(&format!("### `{name}` (`crates/{folder}`)")),
            "{name}: ARCHITECTURE.md has its section"
        );
        // Every entry it defines is charted and cross-checked.
        for line in adapter.lines() {
            let Some(entry) = line
                .trim()
                .strip_prefix("name: \"")
                .and_then(|r| r.strip_suffix("\","))
            else {
                continue;
            };
            assert!(
                pareto.contains(&format!("\"{entry}\"")),
                "{entry}: no run in src/pareto.rs"
            );
            assert!(
                tolerances.contains(&format!("solver = \"{entry}\"")),
                "{entry}: no row in tolerances.toml"
            );
        }
    }
    assert!(solver_crates >= 5, "found {solver_crates} solver crates");
}

#[test]
fn readme_and_ci_agree_on_the_commands() {
    let readme = read("README.md");
    let ci = read(".ci/run");
    assert!(
        readme.contains(TEST_COMMAND) && readme.contains(RUN_COMMAND),
        "README must give both commands"
    );
    assert!(
        ci.lines().any(|l| l.trim() == TEST_COMMAND),
        ".ci/run must run exactly `{TEST_COMMAND}`"
    );
    assert!(ci.contains("set -euo pipefail"));
}

#[test]
fn no_debugging_leftovers() {
    let mut files = Vec::new();
    for dir in ["crates", "src", "xtask", "benches", "examples", "tests"] {
        rust_files(&root().join(dir), &mut files);
    }
    let this_file = root().join(file!());
    // Spelled in pieces so that this file does not match itself.
    let forbidden = [
        concat!("dbg", "!("),
        concat!("todo", "!("),
        concat!("unimplemented", "!("),
    ];
    for file in files.iter().filter(|f| **f != this_file) {
        let text = fs::read_to_string(file).expect("source");
        for pattern in forbidden {
            assert!(
                !text.contains(pattern),
                "{} contains {pattern}",
                file.display()
            );
        }
    }
}

#[test]
fn benchmarks_md_has_its_table() {
    let benchmarks = read("BENCHMARKS.md");
    assert!(
        benchmarks.contains("| what | command | machine | result | date |"),
        "BENCHMARKS.md must keep the what/command/machine/result/date table"
    );
}

/// Files a user of the repository reads: every `.rs`, `.md` and `.toml` below the root, but
/// not build output.
fn user_facing_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if path.is_dir() {
            if name != "target" && !name.starts_with('.') {
                user_facing_files(&path, out);
            }
        } else if path
            .extension()
            .is_some_and(|e| e == "rs" || e == "md" || e == "toml")
        {
            out.push(path);
        }
    }
}

#[test]
fn citations_point_at_what_a_user_has() {
    // The analyses the project was built from, and its issue tracker, are not part of the
    // repository: code and docs cite the paper or thesis (author, chapter, equation) and
    // docs/reference-cases.md, which holds the checked cases and corrections they rely on.
    let forbidden = [
        "shared/notes",
        "anchors.md",
        "note 000",
        "note 001",
        "note 002",
        "note 004",
        "_murray.md",
        "_zhangma.md",
        "_mertens.md",
        "_bernabei.md",
    ];
    let mut files = Vec::new();
    user_facing_files(root(), &mut files);
    let this = root().join(file!());
    let mut offences = Vec::new();
    for file in files.iter().filter(|f| **f != this) {
        let text = fs::read_to_string(file).unwrap_or_default();
        for (n, line) in text.lines().enumerate() {
            let lower = line.to_lowercase();
            let issue = lower
                .match_indices("issue ")
                .any(|(i, _)| lower[i + 6..].starts_with(|c: char| c.is_ascii_digit()));
            if issue || forbidden.iter().any(|f| lower.contains(f)) {
                offences.push(format!("{}:{}: {line}", file.display(), n + 1));
            }
        }
    }
    assert!(offences.is_empty(), "{}", offences.join("\n"));
}

/// The `lucent …` commands the docs show: in code blocks (a line whose program is `lucent`,
/// `target/release/lucent` or `target/debug/lucent`, after environment assignments and an
/// `mpirun … ` prefix, continuation lines joined, comments dropped) and in inline code
/// spans; each with the file and line it came from, as arguments, and whether it is a
/// whole command (a code block's line; an inline span may name a command and its flags
/// without their values). A synopsis is read as its fullest example: brackets dropped, the
/// first of `a|b`, no `...`.
fn documented_commands(path: &Path) -> Vec<(String, Vec<String>, bool)> {
    let text = read(path);
    let name = path
        .strip_prefix(root())
        .unwrap_or(path)
        .display()
        .to_string();
    let mut found = Vec::new();
    let mut in_block = false;
    let mut pending = String::new();
    let mut pending_line = 0;
    for (number, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        if trimmed.starts_with("```") {
            in_block = !in_block;
            continue;
        }
        if in_block {
            let code = trimmed.strip_prefix("$ ").unwrap_or(trimmed);
            let code = match code.find(" #") {
                Some(i) => &code[..i],
                None if code.starts_with('#') => "",
                None => code,
            };
            if pending.is_empty() {
                pending_line = number + 1;
            }
            pending.push_str(code.trim_end_matches('\\'));
            pending.push(' ');
            if code.trim_end().ends_with('\\') {
                continue;
            }
            let joined = std::mem::take(&mut pending);
            if let Some(args) = lucent_arguments(&joined) {
                found.push((format!("{name}:{pending_line}"), args, true));
            }
        } else {
            for (i, span) in line.split('`').enumerate() {
                if i % 2 == 1
                    && span.starts_with("lucent ")
                    && let Some(args) = lucent_arguments(span)
                {
                    found.push((format!("{name}:{}", number + 1), args, false));
                }
            }
        }
    }
    found
}

/// The arguments of `command` when its program is the `lucent` command.
fn lucent_arguments(command: &str) -> Option<Vec<String>> {
    let mut words = command.split_whitespace().peekable();
    // Environment assignments, then an `mpirun` with its options.
    while words
        .peek()
        .is_some_and(|w| w.contains('=') && !w.starts_with('-'))
    {
        words.next();
    }
    if words.peek() == Some(&"mpirun") {
        while words.next_if(|w| !w.ends_with("lucent")).is_some() {}
    }
    let program = words.next()?;
    if !(program == "lucent"
        || program.ends_with("/release/lucent")
        || program.ends_with("/debug/lucent"))
    {
        return None;
    }
    let args: Vec<String> = words
        .filter(|w| !matches!(*w, "..." | "…"))
        .map(|w| {
            let w = w
                .replace(['[', ']'], "")
                .replace("...", "")
                .replace('…', "");
            let w = w.split('|').next().unwrap_or_default().to_owned();
            w.trim_matches(|c| c == '"' || c == '\'').to_owned()
        })
        .filter(|w| !w.is_empty())
        .collect();
    Some(args)
}

/// Every `lucent …` command in README.md, docs/ and examples/README.md parses (it once
/// showed commands that failed: flags before the subcommand, a solver parameter that is
/// no flag): each is run with the hidden `--parse-only`, which checks the command line
/// and exits.
#[test]
fn every_documented_lucent_command_parses() {
    let mut files = vec![root().join("README.md"), root().join("examples/README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    files.extend(docs);
    let mut checked = 0;
    let mut failures = Vec::new();
    for file in &files {
        for (place, args, whole) in documented_commands(file) {
            let out = std::process::Command::new(env!("CARGO_BIN_EXE_lucent"))
                .args(&args)
                .arg("--parse-only")
                .output()
                .unwrap();
            checked += 1;
            let err = String::from_utf8_lossy(&out.stderr);
            // A reference in prose ("`lucent solve --memory-budget` pages ...") names the
            // command and its flags: they must exist, the values may be left out.
            let reference = !whole
                && (err.contains("required arguments were not provided")
                    || err.contains("a value is required"));
            if !out.status.success() && !reference {
                failures.push(format!(
                    "{place}: lucent {}: {}",
                    args.join(" "),
                    String::from_utf8_lossy(&out.stderr)
                        .lines()
                        .next()
                        .unwrap_or("")
                ));
            }
        }
    }
    // The README alone shows a dozen; fewer means the extraction broke.
    assert!(checked >= 20, "only {checked} commands found");
    assert!(
        failures.is_empty(),
        "{} of {checked} commands do not parse:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// Every registered solver has rows in the suite's table (`tolerances.toml`, from which
/// `docs/validation.md` is generated) or is listed, with where it is checked instead, in
/// `crosscheck::CHECKED_ELSEWHERE`, whose section `docs/validation.md` carries
/// (`direct-refractive` had neither).
#[test]
fn every_solver_has_validation_rows_or_a_stated_reason() {
    let (_, tolerances) =
        lucent::crosscheck::load_suite(&root().join("examples/scenes/suite")).unwrap();
    let validation = read("docs/validation.md");
    for entry in lucent::registry().entries() {
        let rows = tolerances.iter().any(|t| t.solver == entry.name);
        let elsewhere = lucent::crosscheck::CHECKED_ELSEWHERE
            .iter()
            .any(|(s, _)| *s == entry.name);
        assert!(
            rows ^ elsewhere,
            "`{}`: rows in tolerances.toml {rows}, in CHECKED_ELSEWHERE {elsewhere} (exactly one)",
            entry.name
        );
        if elsewhere {
            assert!(
                validation.contains(&format!("\n- `{}`: ", entry.name)),
                "docs/validation.md lacks `{}` under \"Solvers without rows in the table\" (cargo xtask crosscheck writes it)",
                entry.name
            );
        } else {
            assert!(
                validation.contains(&format!("\n| {} | ", entry.name)),
                "docs/validation.md has no row of `{}` (cargo xtask crosscheck writes them)",
                entry.name
            );
        }
    }
}

/// What the reader says it expected when `scene` fails with `error` (`"unknown field"` or
/// `"unknown variant"` of the probe): the names serde lists ("expected one of `a`, `b`";
/// "expected `a`"; none for "there are no fields"), sorted.
fn expected_names(scene: &str, error: &str) -> Vec<String> {
    let err = match lucent::scene::Scene::parse(scene, Path::new("probe.toml")) {
        Ok(_) => panic!("the probe was accepted:\n{scene}"),
        Err(e) => e.to_string(),
    };
    assert!(
        err.contains(&format!("{error} `lucent_probe`")),
        "not an {error} error for\n{scene}\n{err}"
    );
    if err.contains("there are no fields") {
        return Vec::new();
    }
    let tail = err
        .split("expected ")
        .nth(1)
        .unwrap_or_else(|| panic!("{err}"));
    let mut names: Vec<String> = tail
        .lines()
        .next()
        .unwrap_or_default()
        .split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_owned)
        .collect();
    names.sort();
    names
}

/// The keys a scene table accepts, as the reader says: a probe key no table has, placed in
/// the table, makes serde name every key it allows.
fn accepted_keys(scene: &str) -> Vec<String> {
    expected_names(scene, "unknown field")
}

/// The `kind` (or `type`) values a tagged table accepts, as the reader says.
fn accepted_variants(scene: &str) -> Vec<String> {
    expected_names(scene, "unknown variant")
}

/// `docs/scene-format.md` is the reference for scene files: each of its key tables lists
/// exactly the keys the reader accepts there (no key missing, none invented), every tagged
/// table has a section for every `kind` (or `type`) the reader knows, and the tone curves
/// named are the reader's.
#[test]
fn the_scene_format_reference_matches_the_reader() {
    let doc = read("docs/scene-format.md");
    // Each "### " heading with the key table under it.
    let mut sections: Vec<(String, Vec<String>)> = Vec::new();
    for line in doc.lines() {
        if let Some(heading) = line.strip_prefix("### ") {
            sections.push((heading.to_owned(), Vec::new()));
        } else if let Some(row) = line.strip_prefix("| `") {
            let key = row.split('`').next().unwrap().to_owned();
            sections
                .last_mut()
                .unwrap_or_else(|| panic!("a key row before any section: {line}"))
                .1
                .push(key);
        }
    }
    // What a section's heading means: the table's path and its tag, and the lines of a
    // scene that reach that table (the parents' tags the table needs).
    let parents = |table: &str| -> &'static str {
        match table {
            "volume.raw" => "[volume]\nkind = \"file\"\npath = \"x.raw\"\n",
            "volume.shape" => "[volume]\nkind = \"shape\"\n",
            _ => "",
        }
    };
    let mut tagged: std::collections::BTreeMap<(String, String), Vec<String>> = Default::default();
    let mut checked = 0;
    for (heading, mut keys) in sections {
        keys.sort();
        let probe = if heading == "Top-level keys" {
            "lucent_probe = 1\n".to_owned()
        } else {
            let mut parts = heading.split('`');
            let _ = parts.next();
            let table = parts
                .next()
                .unwrap_or_else(|| panic!("a section that names no table: {heading}"));
            let rest = parts.next().unwrap_or_default().trim();
            let path = table.trim_matches(['[', ']']);
            let mut probe = parents(path).to_owned();
            probe.push_str(&format!("{table}\n"));
            if let Some((tag, value)) = rest.split_once(" = ") {
                let value = value.trim_matches('"');
                tagged
                    .entry((table.to_owned(), tag.to_owned()))
                    .or_default()
                    .push(value.to_owned());
                probe.push_str(&format!("{tag} = \"{value}\"\n"));
            }
            probe.push_str("lucent_probe = 1\n");
            probe
        };
        let accepted = accepted_keys(&probe);
        // The tag itself is the section's name, not a key of its table.
        assert_eq!(
            keys, accepted,
            "docs/scene-format.md, `{heading}`: the keys listed (left) are not the keys the reader accepts (right)"
        );
        checked += 1;
    }
    assert!(checked >= 30, "{checked} sections checked");
    for ((table, tag), mut documented) in tagged {
        documented.sort();
        let path = table.trim_matches(['[', ']']);
        let probe = format!("{}{table}\n{tag} = \"lucent_probe\"\n", parents(path));
        assert_eq!(
            documented,
            accepted_variants(&probe),
            "docs/scene-format.md: the {tag}s of `{table}`"
        );
    }
    let tones = accepted_variants("[volume]\nkind = \"blob\"\n[image]\ntone = \"lucent_probe\"\n");
    let tone_row = doc
        .lines()
        .find(|l| l.starts_with("| `tone`"))
        .expect("the tone row");
    for tone in tones {
        assert!(
            tone_row.contains(&format!("`\"{tone}\"`")),
            "{tone}: {tone_row}"
        );
    }
}
