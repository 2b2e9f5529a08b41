//! The `lucent` binary end to end: render a scene, solve to `.npy` and read it back, and one
//! clear message with a non-zero exit for each kind of mistake.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn lucent(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lucent"))
        .args(args)
        .current_dir(dir)
        .env("LUCENT_DATA", data_dir())
        .output()
        .expect("the lucent binary runs")
}

fn data_dir() -> PathBuf {
    std::env::var_os("LUCENT_DATA").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/volumes"),
        PathBuf::from,
    )
}

fn scene(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples/scenes")
        .join(name)
        .display()
        .to_string()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// One message (a TOML error may quote the offending line under it), no panic, no
/// backtrace, exit status 1.
fn assert_clean_failure(o: &Output, expected: &str) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(1), "stderr: {err}");
    assert!(err.contains(expected), "expected `{expected}` in: {err}");
    assert!(
        !err.contains("panicked") && !err.contains("backtrace") && !err.contains("RUST_BACKTRACE"),
        "{err}"
    );
    assert!(
        err.starts_with("lucent: ") && err.matches("lucent: ").count() == 1,
        "one message: {err}"
    );
}

/// The README's `cargo run --release`: no arguments render the built-in default scene with
/// `dom` to `lucent.png`, a cloud with visible structure (one render of the default scene
/// serves both checks: it is the costliest test of this file).
#[test]
fn no_arguments_renders_the_default_scene_to_lucent_png() {
    let dir = tempfile::tempdir().unwrap();
    let out = lucent(&[], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains("lucent.png"), "says where: {said}");
    // Multiple scattering, not single scattering alone.
    assert!(said.contains("`dom`"), "{said}");
    let image = image::open(dir.path().join("lucent.png"))
        .unwrap()
        .to_rgb8();
    assert_eq!(image.dimensions(), (640, 480));
    // The cloud is in the middle against the sky: the centre differs from the corner, and
    // its pixels vary (lit and shadowed parts), so it is neither empty nor flat. (The
    // middle half of the view, every fourth pixel.)
    let luminance = |p: &image::Rgb<u8>| {
        0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2])
    };
    let corner = luminance(image.get_pixel(12, 12));
    let centre: Vec<f64> = (160..480)
        .step_by(4)
        .flat_map(|x| (120..360).step_by(4).map(move |y| (x, y)))
        .map(|(x, y)| luminance(image.get_pixel(x, y)))
        .collect();
    let mean = centre.iter().sum::<f64>() / centre.len() as f64;
    let spread = centre.iter().fold(0.0f64, |m, &v| m.max((v - mean).abs()));
    let covered = centre
        .iter()
        .filter(|&&v| (v - corner).abs() > 20.0)
        .count() as f64
        / centre.len() as f64;
    assert!(
        covered > 0.25,
        "the cloud covers the middle of the view: {covered}"
    );
    assert!(
        spread > 40.0,
        "lit and shadowed parts differ: spread {spread}"
    );
}

#[test]
fn renders_exr_too() {
    let dir = tempfile::tempdir().unwrap();
    let out = lucent(
        &[
            "render",
            &scene("rgb_medium.toml"),
            "--size",
            "40x30",
            "-o",
            "blob.exr",
            "--quiet",
            // The file's format is checked, not the fluence: a loose solve.
            "--tolerance",
            "0.3",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let image = image::open(dir.path().join("blob.exr"));
    // The image crate here is built for PNG only; check the EXR magic number instead.
    let bytes = std::fs::read(dir.path().join("blob.exr")).unwrap();
    assert_eq!(
        &bytes[..4],
        &[0x76, 0x2f, 0x31, 0x01],
        "OpenEXR magic ({image:?})"
    );
}

#[test]
fn solves_to_npy_with_a_json_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = lucent(
        &[
            "solve",
            &scene("point_light.toml"),
            "--solver",
            "direct",
            "-o",
            "fluence.npy",
            "--quiet",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let grid =
        lucent::grid::io::npy::read(dir.path().join("fluence.npy"), &Default::default()).unwrap();
    assert_eq!(grid.dims(), [48, 48, 48]);
    let s = grid.stats();
    assert!(
        s.min > 0.0 && s.max.is_finite(),
        "a point light reaches every cell: {s:?}"
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("fluence.json")).unwrap())
            .unwrap();
    assert_eq!(report["solver"], "direct");
    assert_eq!(report["report"]["stop_reason"]["reason"], "exact");
    assert_eq!(report["dims"], serde_json::json!([48, 48, 48]));
    assert!(report["report"]["wall_time_s"].as_f64().unwrap() >= 0.0);
    assert!(report["report"]["peak_memory_bytes"].as_u64().unwrap() > 48 * 48 * 48 * 4);
}

#[test]
fn every_example_scene_is_valid() {
    let dir = tempfile::tempdir().unwrap();
    let scenes =
        std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes")).unwrap();
    let mut count = 0;
    for entry in scenes {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let out = lucent(&["info", &path.display().to_string()], dir.path());
            assert!(out.status.success(), "{}: {}", path.display(), stderr(&out));
            count += 1;
        }
    }
    assert!(count >= 8, "one scene per feature");
}

/// `lucent info` reports the regime: on the homogeneous slab (σ_t = 3, albedo 0.9,
/// isotropic: α′ = 0.9, g = 0) the reduced albedo of the closed form; the slab is 0.5 wide,
/// 1.5 ℓ′, so no region lies 3 ℓ′ from the box.
#[test]
fn info_reports_the_regime() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes/suite/slab.toml");
    let out = lucent(&["info", &scene.display().to_string()], Path::new("."));
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .find(|l| l.trim_start().starts_with("regime"))
        .unwrap_or_else(|| panic!("no regime line:\n{text}"));
    assert!(line.contains("reduced albedo 0.9 (g 0)"), "{line}");
    assert!(line.contains(" 0% of the medium's regions"), "{line}");
    assert!(line.contains("0% of all cells void"), "{line}");
}

/// `lucent resolution` solves the slab (8 × 8 × 32) on its grid and 2× coarser (4× would
/// leave 2 cells across), estimates both errors with the nominal order, and chooses the
/// coarser grid for a loose target and reports the refinement needed for a tight one; a
/// target outside (0, 1) is a usage error.
#[test]
fn resolution_reports_levels_and_the_choice() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes/suite/slab.toml");
    let scene = scene.display().to_string();
    let run = |error: &str| {
        lucent(
            &[
                "resolution",
                &scene,
                "--solver",
                "diffusion-mg",
                "--error",
                error,
            ],
            Path::new("."),
        )
    };
    let loose = run("0.9");
    assert!(loose.status.success(), "{}", stderr(&loose));
    let text = String::from_utf8_lossy(&loose.stdout);
    assert!(text.contains("8 × 8 × 32 cells (1× coarser)"), "{text}");
    assert!(text.contains("4 × 4 × 16 cells (2× coarser)"), "{text}");
    assert!(text.contains("nominal"), "{text}");
    assert!(text.contains("chosen: 4 × 4 × 16 cells meet it"), "{text}");
    let tight = run("1e-9");
    assert!(tight.status.success(), "{}", stderr(&tight));
    let text = String::from_utf8_lossy(&tight.stdout);
    assert!(text.contains("not met"), "{text}");
    let bad = run("-1");
    assert_eq!(bad.status.code(), Some(2), "{}", stderr(&bad));
}

/// `lucent resolution --directions` solves the slab with the hybrid on S8, S4 and S2 and
/// picks the fewest directions for a loose target (S2's 8) and the most for a tight one
/// (not met); a solver without directions is a usage error naming the ones with them.
#[test]
fn resolution_chooses_the_fewest_directions() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes/suite/slab.toml");
    let scene = scene.display().to_string();
    let run = |solver: &str, error: &str| {
        lucent(
            &[
                "resolution",
                &scene,
                "--solver",
                solver,
                "--directions",
                "--error",
                error,
            ],
            Path::new("."),
        )
    };
    let loose = run("hybrid", "0.9");
    assert!(loose.status.success(), "{}", stderr(&loose));
    let text = String::from_utf8_lossy(&loose.stdout);
    for line in [
        "80 directions (order = 8)",
        "24 directions (order = 4)",
        "8 directions (order = 2)",
    ] {
        assert!(text.contains(line), "{line}: {text}");
    }
    assert!(text.contains("chosen: 8 directions meet it"), "{text}");
    let tight = run("hybrid", "1e-9");
    assert!(tight.status.success(), "{}", stderr(&tight));
    let text = String::from_utf8_lossy(&tight.stdout);
    assert!(text.contains("not met: even 80 directions"), "{text}");
    let none = run("diffusion-mg", "0.1");
    assert_eq!(none.status.code(), Some(2), "{}", stderr(&none));
    assert!(stderr(&none).contains("(dom, hybrid)"), "{}", stderr(&none));
}

/// `lucent solvers` is one aligned line per solver (it was 300 lines whose columns broke
/// on names longer than 16); `lucent solvers NAME` is one solver whole.
#[test]
fn lists_solvers_with_capabilities() {
    let out = lucent(&["solvers"], Path::new("."));
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    let entries = lucent::registry().entries().len();
    let lines: Vec<&str> = text.lines().take(entries).collect();
    let column = |line: &str| {
        let name = line.split_whitespace().next().unwrap();
        line[name.len()..].find(|c: char| c != ' ').unwrap() + name.len()
    };
    for (line, entry) in lines.iter().zip(lucent::registry().entries()) {
        assert!(line.starts_with(entry.name), "{text}");
        assert_eq!(column(line), column(lines[0]), "summaries aligned:\n{text}");
    }
    let out = lucent(&["solvers", "direct"], Path::new("."));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("boundaries") && text.contains("directional"),
        "{text}"
    );
    let out = lucent(&["solvers", "no-such-solver"], Path::new("."));
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("no-such-solver"), "{}", stderr(&out));
}

#[test]
fn lists_every_parameter_of_every_solver_with_its_default() {
    let mut text = String::new();
    for entry in lucent::registry().entries() {
        let out = lucent(&["solvers", entry.name], Path::new("."));
        text.push_str(&String::from_utf8_lossy(&out.stdout));
    }
    for entry in lucent::registry().entries() {
        for p in (entry.params)() {
            let line = format!("{} = {}", p.name, p.default);
            assert!(
                text.contains(&line),
                "`{line}` of {} missing:\n{text}",
                entry.name
            );
        }
    }
    assert!(
        text.contains("cycle = \"v\"") && text.contains("order = none"),
        "{text}"
    );
}

#[test]
fn a_bad_solver_parameter_is_one_line_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let base = std::fs::read_to_string(scene("point_light.toml")).unwrap();
    for (solver, param, expected) in [
        ("diffusion-mg", "cycle = \"x\"", "`cycle`"),
        ("diffusion-mg", "cycles = 2", "`cycles`"),
        ("dom", "order = \"eight\"", "`order`"),
        ("mc", "batches = 1", "`batches`"),
        ("ftcs-ordinates", "allow_unstable = 3", "`allow_unstable`"),
    ] {
        let text = format!("{base}\n[solver]\nname = \"{solver}\"\n[solver.params]\n{param}\n");
        std::fs::write(dir.path().join("bad.toml"), text).unwrap();
        for command in ["solve", "info"] {
            let out = lucent(
                &[command, "bad.toml", "-o", "x.npy"][..if command == "info" { 2 } else { 4 }],
                dir.path(),
            );
            assert_clean_failure(&out, expected);
            assert!(stderr(&out).contains(solver), "{}", stderr(&out));
            assert_eq!(
                stderr(&out).trim_end().lines().count(),
                1,
                "{}",
                stderr(&out)
            );
        }
    }
}

/// A scene with one volume file and a sun, for the hostile-input tests.
fn file_scene(volume: &str, extra: &str) -> String {
    format!(
        "[volume]\nkind = \"file\"\npath = \"{volume}\"\n[medium]\ndensity = 1.0\nalbedo = 0.5\n[[lights]]\nkind = \"directional\"\ndirection = [0.0, 0.0, -1.0]\nirradiance = 1.0\n[camera]\nkind = \"pinhole\"\nposition = [3, 0, 0]\nlook_at = [0, 0, 0]\n{extra}"
    )
}

/// Each of these crashed, aborted, hung or wrote NaN before (docs/reliability.md); each
/// must be one line and exit status 1, within seconds.
#[test]
fn hostile_inputs_are_one_clean_line() {
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A gzip NRRD whose header claims 1024³ (5 GiB once decoded) from 64 kB.
    let mut file = std::fs::File::create(d.join("bomb.nrrd")).unwrap();
    file.write_all(
        b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1024 1024 1024\nencoding: gzip\n\n",
    )
    .unwrap();
    let mut gz = flate2::write::GzEncoder::new(file, flate2::Compression::best());
    gz.write_all(&vec![0u8; 16 << 20]).unwrap();
    gz.finish().unwrap();
    std::fs::write(d.join("bomb.toml"), file_scene("bomb.nrrd", "")).unwrap();
    // A detached payload on a device.
    std::fs::write(
        d.join("zero.nrrd"),
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 41 41 41\nencoding: raw\ndata file: /dev/zero\n",
    )
    .unwrap();
    std::fs::write(d.join("zero.toml"), file_scene("zero.nrrd", "")).unwrap();
    // A volume with a NaN voxel.
    let geometry =
        lucent::grid::GridGeometry::new([4, 4, 4], glam::DVec3::ONE, glam::DVec3::ZERO).unwrap();
    // Written by hand: lucent's writers refuse a NaN.
    let mut npy = b"\x93NUMPY\x01\x00".to_vec();
    let mut header = "{'descr': '<f4', 'fortran_order': False, 'shape': (4, 4, 4), }".to_owned();
    while !(10 + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    npy.extend_from_slice(&(header.len() as u16).to_le_bytes());
    npy.extend_from_slice(header.as_bytes());
    for i in 0..64 {
        let v = if i == 21 { f32::NAN } else { 1.0 };
        npy.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(d.join("nan.npy"), npy).unwrap();
    std::fs::write(d.join("nan.toml"), file_scene("nan.npy", "")).unwrap();
    let good = |extra: &str| {
        lucent::grid::io::npy::write(
            d.join("ok.npy"),
            &lucent::grid::Grid::filled(geometry, 1.0),
            lucent::grid::io::ScalarType::F32,
        )
        .unwrap();
        file_scene("ok.npy", extra)
    };
    std::fs::write(d.join("exposure.toml"), good("[image]\nexposure = nan\n")).unwrap();
    std::fs::write(d.join("step.toml"), good("[image]\nstep = 1e-9\n")).unwrap();
    std::fs::write(
        d.join("bright.toml"),
        good("").replace("irradiance = 1.0", "irradiance = 1e300"),
    )
    .unwrap();
    std::fs::write(
        d.join("thick.toml"),
        good("").replace("density = 1.0", "density = 1e8"),
    )
    .unwrap();
    std::fs::write(
        d.join("spp.toml"),
        good("[solver]\nname = \"mc\"\n[solver.params]\nspp = 1000000000000\n"),
    )
    .unwrap();
    let cases: [(&[&str], &str); 12] = [
        (&["info", "bomb.toml"], "over the memory budget"),
        (&["info", "zero.toml"], "not a regular file"),
        (&["info", "/dev/zero"], "not a regular file"),
        (&["info", "nan.toml"], "is NaN"),
        (&["info", "exposure.toml"], "exposure"),
        (&["info", "step.toml"], "step"),
        (&["info", "bright.toml"], "at most 1e30"),
        (
            &["solve", "thick.toml", "--solver", "mc", "-o", "x.npy"],
            "optically thick",
        ),
        (&["render", "spp.toml", "-o", "x.png"], "`spp`"),
        (
            &[
                "render",
                "ok.toml",
                "--solver",
                "mc",
                "--size",
                "9223372036854775808x2",
                "-o",
                "x.png",
            ],
            "image size",
        ),
        (
            &[
                "render",
                "ok.toml",
                "--size",
                "4294967296x4294967296",
                "-o",
                "x.png",
            ],
            "image size",
        ),
        (
            &["render", "ok.toml", "--size", "0x5", "-o", "x.png"],
            "image size",
        ),
    ];
    std::fs::write(d.join("ok.toml"), good("")).unwrap();
    for (args, expected) in cases {
        let started = std::time::Instant::now();
        let out = lucent(args, d);
        assert_clean_failure(&out, expected);
        assert!(
            started.elapsed() < std::time::Duration::from_secs(20),
            "{args:?} took {:?}",
            started.elapsed()
        );
        assert!(
            !d.join("x.png").exists() && !d.join("x.npy").exists(),
            "{args:?} wrote"
        );
    }
}

/// Ctrl-C stops a long solve at its next iteration; what was computed is written, the
/// report says `interrupted`, and the exit status is 130.
#[cfg(unix)]
#[test]
fn ctrl_c_writes_what_was_computed() {
    let dir = tempfile::tempdir().unwrap();
    let slow = DEFAULT_WITH_TYPO
        .replace("[8, 8, 8]", "[96, 96, 96]")
        .replace("densty = 3.0", "density = 20.0\nalbedo = 0.9\n[[lights]]\nkind = \"point\"\nposition = [0.5, 0.5, 0.5]\nintensity = 1.0");
    std::fs::write(dir.path().join("slow.toml"), slow).unwrap();
    let child = Command::new(env!("CARGO_BIN_EXE_lucent"))
        .args([
            "solve",
            "slow.toml",
            "--solver",
            "diffusion-jacobi",
            "-o",
            "phi.npy",
            "--quiet",
        ])
        .current_dir(dir.path())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Jacobi on 96³ to 1e-6 takes far longer than this.
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    let report = std::fs::read_to_string(dir.path().join("phi.json")).unwrap();
    assert!(report.contains("\"interrupted\""), "{report}");
    assert!(dir.path().join("phi.npy").exists());
}

#[test]
fn a_missing_scene_file() {
    let out = lucent(&["render", "no-such-scene.toml"], Path::new("."));
    assert_clean_failure(&out, "no-such-scene.toml");
}

#[test]
fn bad_toml() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("bad.toml"), "[volume\nkind = 3").unwrap();
    let out = lucent(&["render", "bad.toml"], dir.path());
    assert_clean_failure(&out, "bad scene");
    // A well-formed file with a misspelt field is refused too, naming the field.
    std::fs::write(dir.path().join("typo.toml"), DEFAULT_WITH_TYPO).unwrap();
    let out = lucent(&["info", "typo.toml"], dir.path());
    assert_clean_failure(&out, "densty");
}

#[test]
fn an_absurd_resolution_is_refused_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let huge = DEFAULT_WITH_TYPO
        .replace("[8, 8, 8]", "[5000, 5000, 5000]")
        .replace("densty", "density");
    std::fs::write(dir.path().join("huge.toml"), huge).unwrap();
    let out = lucent(&["render", "huge.toml"], dir.path());
    assert_clean_failure(&out, "bytes per field");
    // `info` describes it from the file at once: the medium of 1.25·10¹¹ cells is not
    // evaluated for statistics (that alone would take hours).
    let started = std::time::Instant::now();
    let out = lucent(&["info", "huge.toml"], dir.path());
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(text.contains("5000 × 5000 × 5000"), "{text}");
    assert!(text.contains("statistics not computed"), "{text}");
    assert!(text.contains("500000000000 bytes per field"), "{text}");
    // (A generous bound: a description reads nothing; under load a process starts in
    // well under a second.)
    assert!(
        started.elapsed().as_secs_f64() < 10.0,
        "{:?}",
        started.elapsed()
    );
}

const DEFAULT_WITH_TYPO: &str = "[volume]\nkind = \"blob\"\nresolution = [8, 8, 8]\nbounds = [[0, 0, 0], [1, 1, 1]]\ncentre = [0.5, 0.5, 0.5]\nsigma = 0.2\n[medium]\ndensty = 3.0\n[camera]\nkind = \"pinhole\"\nposition = [3, 0, 0]\nlook_at = [0, 0, 0]\n";

#[test]
fn an_unknown_solver() {
    let out = lucent(
        &["render", "--solver", "magic", "--size", "8x8"],
        Path::new("."),
    );
    assert_clean_failure(&out, "unknown solver `magic`");
}

#[test]
fn a_feature_the_solver_cannot_handle() {
    let out = lucent(
        &["render", &scene("marble_robin.toml"), "--size", "8x8"],
        Path::new("."),
    );
    assert_clean_failure(&out, "cannot handle a Robin boundary");
}

#[test]
fn bad_output_formats_and_sizes() {
    let dir = tempfile::tempdir().unwrap();
    let out = lucent(
        &["render", "--size", "8x8", "-o", "picture.bmp"],
        dir.path(),
    );
    assert_clean_failure(&out, ".png or .exr");
    let out = lucent(&["render", "--size", "eight"], dir.path());
    assert_clean_failure(&out, "WIDTHxHEIGHT");
    let out = lucent(
        &["solve", &scene("point_light.toml"), "-o", "fluence.csv"],
        dir.path(),
    );
    assert_clean_failure(&out, ".npy or .vol");
}

#[test]
fn monte_carlo_renders_with_a_standard_error_image() {
    let dir = tempfile::tempdir().unwrap();
    let out = lucent(
        &[
            "render",
            &scene("rgb_medium.toml"),
            "--solver",
            "mc",
            "--size",
            "24x18",
            "-o",
            "mc.png",
            "--quiet",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(image::open(dir.path().join("mc.png")).unwrap().width(), 24);
    let error = std::fs::read(dir.path().join("mc.stderr.exr")).unwrap();
    assert_eq!(&error[..4], &[0x76, 0x2f, 0x31, 0x01], "OpenEXR magic");
}

// ---------------------------------------------------------------------------------------
// The command line tells the truth: exit status, parameters, outputs, words.

/// `lucent` with extra environment variables.
fn lucent_env(args: &[&str], dir: &Path, env: &[(&str, &str)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lucent"))
        .args(args)
        .current_dir(dir)
        .env("LUCENT_DATA", data_dir())
        .envs(env.iter().copied())
        .output()
        .expect("the lucent binary runs")
}

/// A 10³ box filled with a homogeneous medium and a point light inside: cheap for every
/// solver, homogeneous for `fem-p1-jacobi`.
const SMALL_BOX: &str = "[volume]\nkind = \"shape\"\nresolution = [10, 10, 10]\nbounds = [[-1, -1, -1], [1, 1, 1]]\nshape = { type = \"box\", min = [-2, -2, -2], max = [2, 2, 2] }\n[medium]\ndensity = 4.0\nalbedo = 0.9\n[[lights]]\nkind = \"point\"\nposition = [0.1, 0.05, -0.1]\nintensity = 1.0\n[camera]\nkind = \"pinhole\"\nposition = [4, 0, 0]\nlook_at = [0, 0, 0]\n[image]\nwidth = 16\nheight = 12\n";

fn first_line(o: &Output) -> String {
    stderr(o).lines().next().unwrap_or("").to_owned()
}

#[test]
fn exit_status_and_first_words_say_how_the_solve_ended() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("box.toml"), SMALL_BOX).unwrap();
    // Converged: status 0, nothing on stderr, the image and the fluence written.
    for (command, output) in [("render", "ok.png"), ("solve", "ok.npy")] {
        let out = lucent(
            &[
                command,
                "box.toml",
                "--solver",
                "diffusion-mg",
                "-o",
                output,
                "--quiet",
            ],
            d,
        );
        assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
        assert_eq!(stderr(&out), "");
        assert!(d.join(output).exists());
    }
    // Did not converge (two SOR sweeps): status 3, the words, nothing but the report.
    for (command, output) in [("render", "sor.png"), ("solve", "sor.npy")] {
        let out = lucent(
            &[
                command,
                "box.toml",
                "--solver",
                "diffusion-sor",
                "--max-iterations",
                "2",
                "-o",
                output,
                "--quiet",
            ],
            d,
        );
        assert_eq!(out.status.code(), Some(3), "{}", stderr(&out));
        let line = first_line(&out);
        assert!(
            line.starts_with(
                "lucent: `diffusion-sor` did not converge: stopped at the iteration limit"
            ),
            "{line}"
        );
        assert!(line.contains("--allow-unconverged"), "{line}");
        assert!(
            !d.join(output).exists(),
            "no {output} from an unconverged solve"
        );
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("sor.json")).unwrap()).unwrap();
    assert_eq!(report["converged"], false);
    assert_eq!(report["report"]["stop_reason"]["reason"], "iteration-limit");
    // Asked for: status 0, the image, and the warning.
    let out = lucent(
        &[
            "render",
            "box.toml",
            "--solver",
            "diffusion-sor",
            "--max-iterations",
            "2",
            "--allow-unconverged",
            "-o",
            "sor.png",
            "--quiet",
        ],
        d,
    );
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(
        first_line(&out).contains("written anyway"),
        "{}",
        stderr(&out)
    );
    assert!(d.join("sor.png").exists());
    // Diverged: Murray's P1 Jacobi (spectral radius ≥ 19/8), and FTCS P1 beyond its
    // step bound when the user insists: status 4.
    for args in [
        &["--solver", "fem-p1-jacobi"][..],
        &[
            "--solver",
            "ftcs-p1",
            "--param",
            "allow_unstable=true",
            "--param",
            "step_fraction=1.5",
        ][..],
    ] {
        let mut all = vec!["render", "box.toml", "-o", "diverged.png", "--quiet"];
        all.extend_from_slice(args);
        let out = lucent(&all, d);
        assert_eq!(out.status.code(), Some(4), "{args:?}: {}", stderr(&out));
        let line = first_line(&out);
        assert!(line.contains("diverged"), "{line}");
        assert!(!d.join("diverged.png").exists());
    }
}

#[test]
fn parameters_follow_their_solver_and_the_report_records_what_ran() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = format!(
        "{SMALL_BOX}[solver]\nname = \"diffusion-sor\"\nparams = {{ omega = 1.5 }}\ntolerance = 1e-4\n"
    );
    std::fs::write(d.join("sor.toml"), scene).unwrap();
    let report = |args: &[&str]| -> (serde_json::Value, Output) {
        let mut all = vec![
            "solve",
            "sor.toml",
            "-o",
            "phi.npy",
            "--quiet",
            "--allow-unconverged",
        ];
        all.extend_from_slice(args);
        let out = lucent(&all, d);
        assert_eq!(out.status.code(), Some(0), "{args:?}: {}", stderr(&out));
        let text = std::fs::read_to_string(d.join("phi.json")).unwrap();
        (serde_json::from_str(&text).unwrap(), out)
    };
    // The scene's parameters go with the scene's solver, every default filled in.
    let (r, out) = report(&[]);
    assert_eq!(r["solver"], "diffusion-sor");
    assert_eq!(r["params"]["omega"], 1.5);
    assert_eq!(r["params"]["discretisation"], "embedded");
    assert_eq!(r["options"]["tolerance"], 1e-4);
    assert_eq!(stderr(&out), "");
    // The command line's tolerance over the scene's.
    let (r, _) = report(&["--tolerance", "1e-5"]);
    assert_eq!(r["options"]["tolerance"], 1e-5);
    // --param overrides them.
    let (r, _) = report(&["--param", "omega=1.2"]);
    assert_eq!(r["params"]["omega"], 1.2);
    assert_eq!(r["params_given"]["omega"], 1.2);
    // Another solver runs with its own defaults, says so, and the report shows its own.
    let (r, out) = report(&["--solver", "diffusion-mg", "--param", "cycle=w"]);
    assert_eq!(r["solver"], "diffusion-mg");
    assert_eq!(r["params"]["cycle"], "w");
    assert!(r["params"].get("omega").is_none(), "{}", r["params"]);
    assert!(
        stderr(&out).contains("belong to `diffusion-sor`"),
        "{}",
        stderr(&out)
    );
    // A parameter the solver does not have, and one that is not KEY=VALUE.
    let out = lucent(
        &["solve", "sor.toml", "-o", "phi.npy", "--param", "omgea=1.2"],
        d,
    );
    assert_clean_failure(&out, "`omgea`");
    let out = lucent(
        &["solve", "sor.toml", "-o", "phi.npy", "--param", "omega"],
        d,
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(first_line(&out).contains("KEY=VALUE"), "{}", stderr(&out));
}

#[test]
fn every_output_problem_is_found_before_any_solving() {
    // `dom` on the default scene would take tens of seconds; the counter of solves the
    // process started (printed last with LUCENT_COUNTERS) must stay at zero.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("folder.png")).unwrap();
    let cases: [(&[&str], &str); 8] = [
        (
            &["render", "--solver", "dom", "-o", "x.jpg"],
            ".png or .exr",
        ),
        (
            &["render", "--solver", "dom", "--size", "0x0"],
            "image size",
        ),
        (
            &["render", "--solver", "dom", "--size", "100000x100000"],
            "image size",
        ),
        (
            &["render", "--solver", "dom", "--size", "big"],
            "WIDTHxHEIGHT",
        ),
        (
            &["render", "--solver", "dom", "-o", "/nonexistent/x.png"],
            "does not exist",
        ),
        (
            &["render", "--solver", "dom", "-o", "folder.png"],
            "is a folder",
        ),
        (
            &[
                "solve",
                &scene("point_light.toml"),
                "--solver",
                "dom",
                "-o",
                "x.csv",
            ],
            ".npy or .vol",
        ),
        (
            &[
                "solve",
                &scene("point_light.toml"),
                "--solver",
                "dom",
                "-o",
                "/nonexistent/x.npy",
            ],
            "does not exist",
        ),
    ];
    for (args, expected) in cases {
        let out = lucent_env(args, d, &[("LUCENT_COUNTERS", "1")]);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {}", stderr(&out));
        let line = first_line(&out);
        assert!(
            line.starts_with("lucent: output "),
            "{args:?}: names the output: {line}"
        );
        assert!(line.contains(expected), "{args:?}: {line}");
        assert_eq!(
            stderr(&out).lines().last(),
            Some("lucent: counters: solves started 0"),
            "{args:?}"
        );
    }
}

#[test]
fn info_is_written_for_people() {
    // No Rust debug dumps (`{`, `Some(`, `Rgb(`), and numbers with at most 4 significant
    // digits (no `0.041666666666666664`), for every example scene and the default.
    let dir = tempfile::tempdir().unwrap();
    let mut scenes = vec![String::new()];
    for entry in
        std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes")).unwrap()
    {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            scenes.push(path.display().to_string());
        }
    }
    for s in &scenes {
        let args: Vec<&str> = if s.is_empty() {
            vec!["info"]
        } else {
            vec!["info", s]
        };
        let out = lucent(&args, dir.path());
        assert!(out.status.success(), "{s}: {}", stderr(&out));
        let text = String::from_utf8_lossy(&out.stdout);
        for dump in ["{", "}", "Some(", "None", "Rgb(", "Grey(", "DVec3"] {
            assert!(!text.contains(dump), "{s}: `{dump}` in:\n{text}");
        }
        // A run of 6 or more digits after a decimal point is a raw f64.
        for word in text.split(|c: char| !(c.is_ascii_digit() || c == '.')) {
            if let Some((_, decimals)) = word.split_once('.') {
                assert!(decimals.len() <= 5, "{s}: `{word}` in:\n{text}");
            }
        }
        assert!(
            text.contains("  grid  ") && text.contains("  solver  "),
            "{text}"
        );
    }
}

#[test]
fn vti_volumes_load_in_both_layouts_and_the_vdb_stands_up() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The two vtk.js folders of the shared data, with the README's dims.
    for (name, dims) in [
        ("headsq.vti", "64 × 64 × 93"),
        ("LIDC2.vti", "256 × 256 × 133"),
    ] {
        std::fs::write(d.join("v.toml"), file_scene(&format!("data:{name}"), "")).unwrap();
        let out = lucent(&["info", "v.toml"], d);
        assert!(out.status.success(), "{name}: {}", stderr(&out));
        assert!(
            String::from_utf8_lossy(&out.stdout).contains(dims),
            "{name}"
        );
    }
    // An XML .vti written here (zlib-compressed appended data), 7 × 5 × 9.
    let g = lucent::grid::GridGeometry::new(
        [7, 5, 9],
        glam::DVec3::splat(0.25),
        glam::DVec3::new(-0.875, -0.625, -1.125),
    )
    .unwrap();
    let grid = lucent::grid::Grid::filled(g, 0.5);
    lucent::grid::io::vti::write(
        d.join("x.vti"),
        &grid,
        lucent::grid::io::ScalarType::F32,
        true,
    )
    .unwrap();
    std::fs::write(d.join("x.toml"), file_scene("x.vti", "")).unwrap();
    let out = lucent(&["info", "x.toml"], d);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("7 × 5 × 9") && text.contains("values 0.5 to 0.5"),
        "{text}{}",
        stderr(&out)
    );
    // An unknown format lists the ones lucent reads.
    std::fs::write(d.join("y.xyz"), b"?").unwrap();
    std::fs::write(d.join("y.toml"), file_scene("y.xyz", "")).unwrap();
    assert_clean_failure(&lucent(&["info", "y.toml"], d), ".vti (VTK XML ImageData");
    // The Houdini plume is Y-up: turned Z-up, 111 cells tall along z.
    let out = lucent(&["info", &scene("vdb_smoke.toml")], d);
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("56 × 56 × 111"),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
}

#[test]
fn toml_errors_in_tagged_tables_point_at_the_key() {
    // `[volume]`, `[[lights]]` and `phase` are tagged by `kind`: serde loses the key's
    // place, so the error used to point at the table (line 1 here).
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            DEFAULT_WITH_TYPO
                .replace("sigma = 0.2", "sigmaa = 0.2")
                .replace("densty", "density"),
            "line 6",
            "sigmaa",
        ),
        (
            DEFAULT_WITH_TYPO
                .replace("sigma = 0.2", "sigma = \"wide\"")
                .replace("densty", "density"),
            "line 6",
            "invalid type",
        ),
        (
            format!(
                "{}[[lights]]\nkind = \"point\"\nposition = [0, 0, 0]\nintensty = 1.0\n",
                DEFAULT_WITH_TYPO.replace("densty", "density")
            ),
            "line 16",
            "intensty",
        ),
    ];
    for (text, line, what) in cases {
        std::fs::write(dir.path().join("t.toml"), text).unwrap();
        let out = lucent(&["info", "t.toml"], dir.path());
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(
            err.contains(line) && err.contains(what),
            "expected {line} and {what}: {err}"
        );
    }
}

#[test]
fn options_of_render_work_without_the_word_render() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("box.toml"), SMALL_BOX).unwrap();
    let out = lucent(&["box.toml", "-o", "short.png", "--quiet"], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(dir.path().join("short.png").exists());
    let out = lucent(
        &[
            "-o",
            "default.png",
            "--size",
            "32x24",
            "--quiet",
            // Only the options are checked (the image's size): the loosest solve.
            "--tolerance",
            "0.5",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(
        image::open(dir.path().join("default.png")).unwrap().width(),
        32
    );
}

#[test]
fn errors_blame_the_right_thing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A point light outside the medium: `diffusion-mg` solves it as `dom` and
    // `fem-diffusion` do (its light enters as uncollided light).
    let out = lucent(
        &[
            "render",
            &scene("point_light.toml"),
            "--solver",
            "diffusion-mg",
            "--size",
            "16x16",
            "-o",
            "p.png",
            "--quiet",
        ],
        d,
    );
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    // Non-cubic cells are named as such, an out-of-range parameter by its name.
    let flat = SMALL_BOX.replace("resolution = [10, 10, 10]", "resolution = [10, 5, 10]");
    std::fs::write(d.join("flat.toml"), flat).unwrap();
    let out = lucent(
        &[
            "render",
            "flat.toml",
            "--solver",
            "fem-diffusion",
            "-o",
            "f.png",
        ],
        d,
    );
    assert_clean_failure(&out, "cannot handle non-cubic cells");
    std::fs::write(d.join("box.toml"), SMALL_BOX).unwrap();
    let out = lucent(
        &[
            "render",
            "box.toml",
            "--solver",
            "diffusion-sor",
            "--param",
            "omega=2.5",
            "-o",
            "f.png",
        ],
        d,
    );
    assert_clean_failure(&out, "invalid parameter `omega`: in (0, 2)");
}

#[test]
fn monte_carlo_that_took_every_path_is_a_finished_solve() {
    // A Monte Carlo run that traced every particle asked for is complete (exit 0, stop
    // reason `sampled` with its standard error), not stopped at an iteration limit.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("box.toml"), SMALL_BOX).unwrap();
    let out = lucent(
        &[
            "solve",
            "box.toml",
            "--solver",
            "mc",
            "--param",
            "particles=20000",
            "-o",
            "mc.npy",
            "--quiet",
        ],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("mc.json")).unwrap())
            .unwrap();
    assert_eq!(report["report"]["stop_reason"]["reason"], "sampled");
    let error = report["report"]["stop_reason"]["relative_error"]
        .as_f64()
        .unwrap();
    assert!(error > 0.0 && error < 1.0, "{error}");
    // The per-cell standard errors are written beside the fluence (`mc.stderr.npy`, named
    // in the report), and they are the ones the reported error summarises: its mean
    // relative error over the cells above a thousandth of the peak, recomputed from the two
    // files (f32 values, summed in f64 in the same order: equal to rounding).
    assert_eq!(report["standard_error"], "mc.stderr.npy");
    let load = |name: &str| {
        lucent::grid::io::npy::read(dir.path().join(name), &Default::default())
            .unwrap()
            .data()
            .to_vec()
    };
    let (phi, se) = (load("mc.npy"), load("mc.stderr.npy"));
    assert_eq!(phi.len(), se.len());
    assert!(se.iter().all(|e| e.is_finite() && *e >= 0.0));
    let peak = phi.iter().copied().fold(0.0f32, f32::max);
    let (sum, count) = phi
        .iter()
        .zip(&se)
        .filter(|(p, _)| **p > 1e-3 * peak)
        .fold((0.0, 0usize), |(s, n), (p, e)| {
            (s + f64::from(*e / *p), n + 1)
        });
    let recomputed = sum / count as f64;
    assert!(
        (recomputed - error).abs() <= 1e-9 * error,
        "{recomputed} vs the report's {error}"
    );
}

#[test]
fn default_courant_number_fits_the_scene_at_hand() {
    // Zhang & Ma's upwind models under an oblique sun whose bound is below the paper's ½
    // (|u| + |v| + |w| = 1.59 at (−0.3, −0.4, −0.8), plus h·σ_a for the conservative form):
    // the default comes from the bound, so the ordinary scene runs.
    let dir = tempfile::tempdir().unwrap();
    let sun = SMALL_BOX.replace(
        "kind = \"point\"\nposition = [0.1, 0.05, -0.1]\nintensity = 1.0",
        "kind = \"directional\"\ndirection = [-0.3, -0.4, -0.8]\nirradiance = 1.0",
    );
    std::fs::write(dir.path().join("sun.toml"), sun).unwrap();
    for model in ["conservative", "paper"] {
        let out = lucent(
            &[
                "render",
                "sun.toml",
                "--solver",
                "convection-diffusion",
                "--param",
                &format!("model={model}"),
                "-o",
                "zm.png",
                "--quiet",
            ],
            dir.path(),
        );
        assert_eq!(out.status.code(), Some(0), "{model}: {}", stderr(&out));
    }
}

#[test]
fn ctrl_c_during_a_path_traced_render_writes_the_rows_traced() {
    // Path tracing the default cloud at 640×480 takes about a minute; a Ctrl-C after a
    // second stops starting rows, and the picture and its error image are written with
    // what was traced (exit 130), instead of the process dying.
    let dir = tempfile::tempdir().unwrap();
    let child = Command::new(env!("CARGO_BIN_EXE_lucent"))
        .args(["render", "--solver", "mc", "-o", "mc.png", "--quiet"])
        .current_dir(dir.path())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let out = child.wait_with_output().unwrap();
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(130), "{err}");
    assert!(err.contains("rows traced"), "{err}");
    assert_eq!(image::open(dir.path().join("mc.png")).unwrap().width(), 640);
    assert!(dir.path().join("mc.stderr.exr").exists());
}

#[test]
fn a_gpu_backend_without_an_adapter_is_one_line_saying_so() {
    // WGPU_ADAPTER_NAME that matches nothing: the same as a machine without a driver.
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_lucent"))
        .args([
            "solve",
            &scene("spot_light.toml"),
            "--solver",
            "gpu-direct",
            "-o",
            "fluence.npy",
            "--quiet",
        ])
        .current_dir(dir.path())
        .env("LUCENT_DATA", data_dir())
        .env("WGPU_ADAPTER_NAME", "no adapter has this name")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let err = stderr(&out);
    assert!(
        err.contains("gpu-direct") && err.contains("no GPU adapter"),
        "{err}"
    );
    assert!(!dir.path().join("fluence.npy").exists());
}

#[test]
fn gpu_direct_writes_what_direct_writes() {
    let Some(_) = lucent::gpu::context_or_skip("gpu_direct_writes_what_direct_writes") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    for solver in ["direct", "gpu-direct"] {
        let out = lucent(
            &[
                "solve",
                &scene("spot_light.toml"),
                "--solver",
                solver,
                "-o",
                &format!("{solver}.npy"),
                "--quiet",
            ],
            dir.path(),
        );
        assert!(out.status.success(), "{solver}: {}", stderr(&out));
    }
    let read = |name: &str| {
        lucent::grid::io::npy::read(dir.path().join(name), &Default::default()).unwrap()
    };
    let (cpu, gpu) = (read("direct.npy"), read("gpu-direct.npy"));
    let peak = f64::from(cpu.stats().max);
    let worst = cpu
        .data()
        .iter()
        .zip(gpu.data())
        .map(|(a, b)| f64::from((a - b).abs()))
        .fold(0.0, f64::max);
    // f32 optical depths on the device against f64 on the host (lucent-gpu-solvers'
    // `direct` docs): 10⁻⁴ of the peak.
    assert!(worst < 1e-4 * peak, "{worst} of {peak}");
}

/// The linear pixels of an EXR file the renderer wrote, row-major.
fn read_exr(path: &Path) -> Vec<[f32; 3]> {
    let image = exr::prelude::read_first_rgba_layer_from_file(
        path,
        |size, _| (size.width(), vec![[0f32; 3]; size.width() * size.height()]),
        |(width, pixels): &mut (usize, Vec<[f32; 3]>), at, (r, g, b, _): (f32, f32, f32, f32)| {
            pixels[at.y() * *width + at.x()] = [r, g, b];
        },
    );
    image.unwrap().layer_data.channel_data.pixels.1
}

#[test]
fn render_gpu_draws_the_cpu_picture() {
    let Some(_) = lucent::gpu::context_or_skip("render_gpu_draws_the_cpu_picture") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    // A cloud lit by the sun through `direct` (per-light transmittance, double
    // Henyey–Greenstein) and the default scene through `dom` (discrete ordinates).
    for (scene_file, name) in [
        ("backlit_anisotropic.toml", "backlit"),
        ("default.toml", "default"),
    ] {
        let mut images = Vec::new();
        for gpu in [false, true] {
            let output = format!("{name}-{gpu}.exr");
            let mut args = vec![
                "render",
                &scene(scene_file) as &str,
                "--size",
                "45x31",
                "-o",
                &output,
                "--quiet",
            ]
            .into_iter()
            .map(str::to_owned)
            .collect::<Vec<_>>();
            if gpu {
                args.push("--gpu".into());
            }
            if name == "default" {
                // The march is compared, not the fluence it marches through: `dom` to a
                // loose tolerance (the same fluence both times: the solve is deterministic).
                args.extend(["--tolerance".into(), "0.3".into()]);
            }
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            let out = lucent(&args, dir.path());
            assert!(out.status.success(), "{name} gpu={gpu}: {}", stderr(&out));
            images.push(read_exr(&dir.path().join(&output)));
        }
        let peak = images[0].iter().flatten().fold(0f32, |m, v| m.max(*v));
        let worst = images[0]
            .iter()
            .zip(&images[1])
            .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
            .fold(0f32, f32::max);
        // The marches are the same but for f32 on the device (lucent-render's `gpu`
        // docs): about N·2⁻²⁴ relative over the N ≈ 200 steps across these grids, plus
        // the 10⁻⁴ opacity cut-off landing one step apart in a dense cloud. Measured:
        // 1.6·10⁻⁵ (backlit) and 1.2·10⁻⁶ (default) of the peak; asserted at 10⁻⁴.
        assert!(
            peak > 0.0 && worst <= 1e-4 * peak,
            "{name}: {worst} of {peak}"
        );
    }
}

#[test]
fn render_gpu_without_an_adapter_fails_before_solving() {
    let dir = tempfile::tempdir().unwrap();
    let out = lucent_env(
        &[
            "render",
            &scene("spot_light.toml"),
            "--gpu",
            "-o",
            "x.png",
            "--quiet",
        ],
        dir.path(),
        &[
            ("WGPU_ADAPTER_NAME", "no adapter has this name"),
            ("LUCENT_COUNTERS", "1"),
        ],
    );
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("no GPU adapter"), "{err}");
    assert!(err.ends_with("solves started 0\n"), "{err}");
    assert!(!dir.path().join("x.png").exists());
    // Monte Carlo draws its own picture: --gpu has nothing to march there.
    let out = lucent(
        &[
            "render",
            &scene("spot_light.toml"),
            "--solver",
            "mc",
            "--gpu",
            "-o",
            "y.png",
            "--quiet",
        ],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("--gpu"), "{}", stderr(&out));
}

#[test]
fn a_memory_budget_refuses_before_allocating_naming_the_bytes() {
    let dir = tempfile::tempdir().unwrap();
    // The solver's estimate is over 1 MiB; the scene's 32³ fields fit.
    let out = lucent_env(
        &[
            "solve",
            &scene("marble_robin.toml"),
            "--solver",
            "diffusion-mg",
            "--memory-budget",
            "1MiB",
            "-o",
            "x.npy",
            "--quiet",
        ],
        dir.path(),
        &[("LUCENT_COUNTERS", "1")],
    );
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("diffusion-mg") && err.contains("over the memory budget of 1048576 bytes"),
        "{err}"
    );
    assert!(err.ends_with("solves started 0\n"), "{err}");
    // The scene's own fields over the budget: refused while building it (diffusion-mg
    // needs its fields in memory).
    let out = lucent(
        &[
            "solve",
            &scene("marble_robin.toml"),
            "--solver",
            "diffusion-mg",
            "--memory-budget",
            "64KiB",
            "-o",
            "x.npy",
            "--quiet",
        ],
        dir.path(),
    );
    assert_clean_failure(&out, "131072 bytes per field");
    assert!(!dir.path().join("x.npy").exists());
    // A budget that is not a size is a usage error.
    let out = lucent(
        &[
            "solve",
            &scene("marble_robin.toml"),
            "--memory-budget",
            "12parsecs",
            "-o",
            "x.npy",
        ],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("unknown unit"), "{}", stderr(&out));
    // Within the budget it runs.
    let out = lucent(
        &[
            "solve",
            &scene("marble_robin.toml"),
            "--solver",
            "diffusion-mg",
            "--memory-budget",
            "64MiB",
            "-o",
            "x.npy",
            "--quiet",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
}

#[test]
fn a_scene_beyond_the_budget_is_solved_out_of_core_to_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    // The backlit cloud's 48³ fields are 442 kB each; a 1 MiB budget holds no dense scene,
    // so `direct`, `convection-diffusion`, `mc` and the steady diffusion schemes page
    // (bricks of 4³, a pool of a few hundred; `mc` and the steady schemes give the medium
    // half the budget and page their own data in the rest).
    // `mc` in memory takes the bricks' majorant blocks, 4³, so that both trace alike.
    let mc: &[&str] = &[
        "--param",
        "particles=300",
        "--param",
        "batches=3",
        "--param",
        "majorant_cells=4",
    ];
    // The steady diffusion schemes stop at an iteration limit here (FTCS needs thousands
    // of steps at 48³); the paged run must stop at the same step with the same bits.
    // Their windows of slabs and first-collision layers need 1.8 MB beside the pools at 48²
    // (in memory they assemble 66 MB), so they get 2 MiB.
    let steady: &[&str] = &["--max-iterations", "40", "--allow-unconverged"];
    for (solver, params, budget) in [
        ("direct", &[][..], "1MiB"),
        ("convection-diffusion", &[], "1MiB"),
        ("mc", mc, "1MiB"),
        ("ftcs-diffusion", steady, "2MiB"),
        ("jacobi-diffusion", steady, "2MiB"),
    ] {
        let run = |out: &str, budget: Option<&str>| {
            let mut args = vec![
                "solve",
                &scene("backlit_anisotropic.toml") as &str,
                "--solver",
                solver,
                "-o",
                out,
                "--quiet",
            ]
            .into_iter()
            .chain(params.iter().copied())
            .map(str::to_owned)
            .collect::<Vec<_>>();
            if let Some(b) = budget {
                args.extend(["--memory-budget".to_owned(), b.to_owned()]);
            }
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            let o = lucent(&args, dir.path());
            assert!(o.status.success(), "{solver} {budget:?}: {}", stderr(&o));
        };
        run("memory.npy", None);
        run("paged.npy", Some(budget));
        let read = |n: &str| std::fs::read(dir.path().join(n)).unwrap();
        assert!(
            read("memory.npy") == read("paged.npy"),
            "{solver}: the files differ"
        );
        let report: serde_json::Value = serde_json::from_slice(&read("paged.json")).unwrap();
        assert_eq!(report["storage"], "paged", "{report}");
        // Monte Carlo's per-cell standard error goes beside the fluence, in memory and out
        // of core alike; the other solvers have none to write.
        for run in ["memory", "paged"] {
            let errors = dir.path().join(format!("{run}.stderr.npy"));
            let report: serde_json::Value =
                serde_json::from_slice(&read(&format!("{run}.json"))).unwrap();
            if solver == "mc" {
                assert_eq!(report["standard_error"], format!("{run}.stderr.npy"));
                assert!(errors.exists(), "{run}");
            } else {
                assert!(report["standard_error"].is_null(), "{report}");
                assert!(!errors.exists(), "{solver} {run}");
            }
        }
        if solver == "mc" {
            assert!(
                read("memory.stderr.npy") == read("paged.stderr.npy"),
                "mc: the standard errors differ"
            );
            std::fs::remove_file(dir.path().join("memory.stderr.npy")).unwrap();
            std::fs::remove_file(dir.path().join("paged.stderr.npy")).unwrap();
        }
        assert!(
            report["report"]["paging"]["evictions"].as_u64().unwrap() > 0,
            "{report}"
        );
        assert!(
            report["report"]["paging"]["bytes_written"]
                .as_u64()
                .unwrap()
                > 0,
            "{report}"
        );
    }
    // Out of core the fluence is streamed as .npy only.
    let out = lucent(
        &[
            "solve",
            &scene("backlit_anisotropic.toml"),
            "--memory-budget",
            "1MiB",
            "-o",
            "x.vol",
        ],
        dir.path(),
    );
    assert_clean_failure(&out, ".npy");
    // A solver that needs its fields in memory: the scene's own check refuses, naming bytes.
    let out = lucent(
        &[
            "solve",
            &scene("backlit_anisotropic.toml"),
            "--solver",
            "diffusion-mg",
            "--memory-budget",
            "1MiB",
            "-o",
            "y.npy",
        ],
        dir.path(),
    );
    assert_clean_failure(&out, "bytes per field");
}

/// `lucent solve --solver auto` says in one line what it chose and why, records it in the
/// report, and says so when the tolerance cannot be met.
#[test]
fn auto_says_what_it_chose_and_why() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let slab = scene("suite/slab.toml");
    let solve = |tolerance: &str| {
        let out = lucent(
            &[
                "solve",
                &slab,
                "--solver",
                "auto",
                "--param",
                &format!("tolerance={tolerance}"),
                "-o",
                "phi.npy",
                "--quiet",
            ],
            d,
        );
        assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
        let said: Vec<String> = stderr(&out)
            .lines()
            .filter(|l| l.starts_with("lucent: auto"))
            .map(str::to_owned)
            .collect();
        assert_eq!(said.len(), 1, "{}", stderr(&out));
        let report: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join("phi.json")).unwrap()).unwrap();
        assert_eq!(report["solver"], "auto");
        assert_eq!(
            format!("lucent: {}", report["report"]["choice"].as_str().unwrap()),
            said[0]
        );
        // What ran, as fields (it was only in the line): the chosen solver, its full
        // parameters, and the numbers of the decision.
        let composition = &report["report"]["composition"];
        let solver = composition["solver"].as_str().unwrap();
        assert_ne!(solver, "auto");
        assert!(said[0].contains(&format!("`{solver}`")), "{}", said[0]);
        assert_eq!(report["ran"]["solver"], solver);
        assert_eq!(report["ran"]["params"], composition["params"]);
        assert!(
            composition["params"]
                .as_object()
                .is_some_and(|p| !p.is_empty()),
            "{composition}"
        );
        let decision = &composition["decision"];
        assert_eq!(
            decision["tolerance"].as_f64().unwrap(),
            tolerance.parse::<f64>().unwrap()
        );
        assert_eq!(decision["neighbours"][0]["scene"], "slab");
        assert!(
            decision["neighbours"][0]["regime_distance"]
                .as_f64()
                .unwrap()
                < 0.05
        );
        said[0].clone()
    };
    let loose = solve("0.2");
    assert!(
        loose.starts_with("lucent: auto chose `") && loose.contains("this suite scene, slab"),
        "{loose}"
    );
    let tight = solve("1e-4");
    assert!(
        tight.starts_with("lucent: auto cannot meet 0.01%"),
        "{tight}"
    );
}

/// On a scene the suite has not measured, `auto` asks a run to come within a margin of
/// the tolerance: the line says so, with the limit, and labels the regime distances ("auto
/// cannot meet 5.00 % … with 4.29 %" read as a contradiction).
#[test]
fn auto_names_its_margin_on_a_scene_it_has_not_measured() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = lucent(
        &[
            "solve",
            &scene("point_light.toml"),
            "--solver",
            "auto",
            "--param",
            "tolerance=0.05",
            "-o",
            "phi.npy",
            "--quiet",
            "--allow-unconverged",
        ],
        d,
    );
    assert!(matches!(out.status.code(), Some(0 | 3)), "{}", stderr(&out));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("phi.json")).unwrap()).unwrap();
    let decision = &report["report"]["composition"]["decision"];
    let limit = decision["error_limit"].as_f64().unwrap();
    assert!((limit - 0.04).abs() < 1e-12, "{decision}");
    let line = report["report"]["choice"].as_str().unwrap();
    assert!(
        line.contains("(at most 4.00% measured: a margin of 20 %"),
        "{line}"
    );
    assert!(line.contains("regime distance"), "{line}");
}

/// `hybrid` says in one line what its parts did and records them as fields: the uncollided
/// light, the orders swept, the diffused rest with its V-cycles (it printed nothing).
#[test]
fn hybrid_reports_its_parts() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = lucent(
        &[
            "solve",
            &scene("suite/slab.toml"),
            "--solver",
            "hybrid",
            "--param",
            "orders=2",
            "-o",
            "phi.npy",
        ],
        d,
    );
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("lucent: hybrid ran "),
        "{}",
        stderr(&out)
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("phi.json")).unwrap()).unwrap();
    let composition = &report["report"]["composition"];
    assert_eq!(composition["solver"], "hybrid");
    assert_eq!(report["ran"]["params"]["orders"], 2);
    let parts = composition["parts"].as_array().unwrap();
    let methods: Vec<&str> = parts
        .iter()
        .map(|p| p["method"].as_str().unwrap())
        .collect();
    assert_eq!(methods.last(), Some(&"diffusion-mg"), "{composition}");
    assert!(
        methods.iter().any(|m| m.contains("sweeps")),
        "{composition}"
    );
    let swept = parts
        .iter()
        .find(|p| p["method"].as_str().unwrap().contains("sweeps"))
        .unwrap();
    // At most two orders swept per channel, at least one.
    let sweeps = swept["iterations"].as_u64().unwrap();
    assert!(sweeps >= 1, "{composition}");
    let rest = parts.last().unwrap();
    let share = rest["share"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&share), "{composition}");
    assert!(rest["iterations"].as_u64().unwrap() >= 1, "{composition}");
}

// ---------------------------------------------------------------------------------------
// The reliability probe of 2026-11-28 (docs/reliability.md, "Round of 2026-11-28"): each
// test failed before its fix.
// ---------------------------------------------------------------------------------------

/// Global flags go before the subcommand as in cargo and git (`lucent -q solve ...` once
/// failed: the top-level `[SCENE]` shorthand took `solve` for a scene file); `render`'s
/// own arguments before a subcommand are a usage error naming them.
#[test]
fn global_flags_go_before_the_subcommand() {
    let dir = tempfile::tempdir().unwrap();
    let slab = scene("suite/slab.toml");
    let out = lucent(&["-q", "solve", &slab, "-o", "phi.npy"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(dir.path().join("phi.npy").exists());
    let out = lucent(&["--quiet", "info", &slab], dir.path());
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let out = lucent(
        &["--solver", "dom", "solve", &slab, "-o", "x.npy"],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("`--solver` given before the subcommand `solve`"));
    // The shorthand still renders.
    let out = lucent(
        &["-q", &slab, "-o", "short.png", "--size", "8x6"],
        dir.path(),
    );
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(dir.path().join("short.png").exists());
}

/// A full stdout (`> /dev/full`) loses the lines, not the job: `println!` panicked (exit
/// 101) after the result was written.
#[cfg(target_os = "linux")]
#[test]
fn a_full_stdout_never_panics() {
    let dir = tempfile::tempdir().unwrap();
    let slab = scene("suite/slab.toml");
    for args in [
        vec!["solve", slab.as_str(), "-o", "phi.npy"],
        vec!["render", slab.as_str(), "-o", "x.png", "--size", "8x6"],
        vec!["solvers"],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_lucent"))
            .args(&args)
            .current_dir(dir.path())
            .stdout(std::fs::File::create("/dev/full").unwrap())
            .output()
            .unwrap();
        let err = stderr(&out);
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        // The result is written (the report lines are lost); `solvers` prints nothing else,
        // so it fails cleanly with the device's error.
        if args[0] == "solvers" {
            assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
            assert!(err.contains("No space left"), "{err}");
        } else {
            assert_eq!(out.status.code(), Some(0), "{args:?}: {err}");
        }
    }
    assert!(dir.path().join("phi.npy").exists() && dir.path().join("x.png").exists());
}

/// Numbers that cannot mean anything are refused, naming them: a non-finite parameter
/// (JSON turned NaN and infinity into null, which an optional parameter read as "unset"),
/// a relative tolerance of 1 or more (the initial guess would be converged), no scattering
/// event allowed to a Monte Carlo path, and a 1³ grid for `resolution` (its "2× coarser"
/// grid was itself, so the estimate was 0 and "met").
#[test]
fn numbers_that_cannot_mean_anything_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let slab = scene("suite/slab.toml");
    let cases: [(&[&str], &str); 6] = [
        (
            &["--solver", "convection-diffusion", "--param", "courant=nan"],
            "`courant`: NaN is not a finite number",
        ),
        (
            &["--solver", "dom", "--param", "order=inf"],
            "`order`: inf is not a finite number",
        ),
        (
            &["--param", "max_optical_depth=-inf"],
            "`max_optical_depth`: -inf is not a finite number",
        ),
        (&["--tolerance", "2"], "--tolerance 2.0"),
        (&["--tolerance", "1"], "--tolerance 1.0"),
        (
            &["--solver", "mc", "--param", "max_depth=0"],
            "`max_depth`: at least 1",
        ),
    ];
    for (extra, expected) in cases {
        let mut args = vec!["solve", slab.as_str(), "-o", "x.npy", "-q"];
        args.extend_from_slice(extra);
        let out = lucent(&args, dir.path());
        let err = stderr(&out);
        assert!(matches!(out.status.code(), Some(1 | 2)), "{extra:?}: {err}");
        assert!(
            err.contains(expected),
            "{extra:?}: expected `{expected}` in {err}"
        );
        assert!(!dir.path().join("x.npy").exists());
    }
    let one = std::fs::read_to_string(scene("suite/slab.toml"))
        .unwrap()
        .replace("resolution = [8, 8, 32]", "resolution = [1, 1, 1]");
    std::fs::write(dir.path().join("one.toml"), one).unwrap();
    let out = lucent(&["resolution", "one.toml"], dir.path());
    assert_clean_failure(&out, "no grid 2× coarser");
}

/// A box that reaches infinity (spacing 1e308) is refused, not solved to 1.0 everywhere.
#[test]
fn geometry_that_overflows_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let huge = std::fs::read_to_string(scene("suite/slab.toml"))
        .unwrap()
        .replace("[0.5, 0.5, 2.0]", "[0.5, 0.5, 1e308]");
    std::fs::write(dir.path().join("huge.toml"), huge).unwrap();
    let out = lucent(&["solve", "huge.toml", "-o", "x.npy", "-q"], dir.path());
    assert_clean_failure(&out, "reaches beyond ±1e150");
    assert!(!dir.path().join("x.npy").exists());
}

/// Messages print numbers as numbers: 1e300 as `1e300`, not 301 digits; NaN as `NaN`,
/// not `null`.
#[test]
fn messages_print_numbers_as_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let slab = scene("suite/slab.toml");
    let cases: [&[&str]; 4] = [
        &["--time-limit", "1e300"],
        &[
            "--solver",
            "ftcs-diffusion",
            "--param",
            "step_fraction=1e300",
        ],
        &["--param", "max_optical_depth=nan"],
        &[
            "--solver",
            "convection-diffusion",
            "--param",
            "model=conservative",
            "--param",
            "courant=1e300",
        ],
    ];
    for extra in cases {
        let mut args = vec!["solve", slab.as_str(), "-o", "x.npy", "-q"];
        args.extend_from_slice(extra);
        let out = lucent(&args, dir.path());
        let err = stderr(&out);
        assert!(matches!(out.status.code(), Some(1 | 2)), "{extra:?}: {err}");
        let longest_digits = err
            .split(|c: char| !c.is_ascii_digit())
            .map(str::len)
            .max()
            .unwrap_or(0);
        assert!(longest_digits < 20, "{extra:?}: {err}");
        assert!(!err.contains("null"), "{extra:?}: {err}");
    }
}

/// `RAYON_NUM_THREADS` beyond 1024 is capped (100 000 threads never finished starting).
#[test]
fn a_huge_thread_count_in_the_environment_is_capped() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_lucent"))
        .args(["solve", &scene("suite/slab.toml"), "-o", "phi.npy", "-q"])
        .current_dir(dir.path())
        .env("RAYON_NUM_THREADS", "100000")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(stderr(&out).contains("RAYON_NUM_THREADS=100000 capped at 1024 threads"));
}

/// A compute-only GPU run on a headless machine prints no window-system errors (Mesa's
/// device-select layer made libwayland print `error: XDG_RUNTIME_DIR is invalid or not set`
/// twice on every run).
#[test]
fn a_headless_gpu_run_prints_no_window_system_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_lucent"))
        .args(["solve", &scene("suite/slab.toml"), "--solver", "gpu-direct"])
        .args(["-o", "phi.npy", "-q"])
        .current_dir(dir.path())
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("NODEVICE_SELECT")
        .output()
        .unwrap();
    let err = stderr(&out);
    let ci = std::env::var("CI").is_ok_and(|v| v == "true" || v == "1");
    if out.status.code() == Some(1) && err.contains("adapter") && !ci {
        eprintln!("skipped: no GPU adapter ({err})");
        return;
    }
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(!err.contains("XDG_RUNTIME_DIR"), "{err}");
    assert!(err.is_empty(), "a quiet run says nothing: {err}");
    // Without -q, a run on a software device (lavapipe here) says so once, naming it.
    let out = Command::new(env!("CARGO_BIN_EXE_lucent"))
        .args(["solve", &scene("suite/slab.toml"), "--solver", "gpu-direct"])
        .args(["-o", "phi.npy"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(0), "{err}");
    let said = err.matches("is a software device").count();
    let software = lucent::gpu::GpuContext::shared().is_ok_and(|d| d.is_software());
    assert_eq!(said, usize::from(software), "{err}");
}

/// `lucent ARGS` in `dir` under a file-size limit of `blocks` × 512 bytes: a full disk as
/// a writer sees it (`EFBIG` partway through a file, `SIGXFSZ` ignored).
#[cfg(unix)]
fn lucent_on_a_full_disk(args: &[&str], dir: &Path, blocks: u32) -> Output {
    Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -f {blocks}; trap '' XFSZ; exec \"$0\" \"$@\""
        ))
        .arg(env!("CARGO_BIN_EXE_lucent"))
        .args(args)
        .current_dir(dir)
        .env("LUCENT_DATA", data_dir())
        .output()
        .expect("sh runs")
}

/// Every output of the command onto a full disk: exit 1 with the file named, the older
/// file at the target intact, and no partial file beside it. (A small PNG once sat in a
/// buffer whose failed flush was dropped: "rendered", exit 0, a 0-byte file.)
#[cfg(unix)]
#[test]
fn outputs_onto_a_full_disk_fail_and_keep_the_older_file() {
    let slab = scene("suite/slab.toml");
    // A 2 × 2 × 2 medium: its fluence (.npy 160 bytes, .vol 80) fits under the limit, its
    // JSON report does not, so the report's own failure is seen.
    let tiny = std::fs::read_to_string(&slab)
        .unwrap()
        .replace("resolution = [8, 8, 32]", "resolution = [2, 2, 2]");
    let cases: Vec<(Vec<&str>, Vec<&str>, &str)> = vec![
        // (arguments, outputs that exist before, the output that must fail)
        (
            vec!["render", &slab, "-o", "x.png", "--size", "128x96"],
            vec!["x.png"],
            "x.png",
        ),
        (
            vec!["render", &slab, "-o", "x.exr", "--size", "64x48"],
            vec!["x.exr"],
            "x.exr",
        ),
        (
            vec![
                "render", &slab, "-o", "mc.png", "--size", "64x48", "--solver", "mc", "--param",
                "spp=2",
            ],
            vec!["mc.png", "mc.stderr.exr"],
            "mc.stderr.exr",
        ),
        (
            vec!["solve", &slab, "-o", "phi.npy"],
            vec!["phi.npy", "phi.json"],
            "phi.npy",
        ),
        (
            vec!["solve", &slab, "-o", "phi.vol"],
            vec!["phi.vol", "phi.json"],
            "phi.vol",
        ),
        (
            vec!["solve", "tiny.toml", "-o", "tiny.npy"],
            vec!["tiny.json"],
            "tiny.json",
        ),
        // Out of core: the fluence streamed slab by slab into the .npy.
        (
            vec![
                "solve",
                &slab,
                "-o",
                "paged.npy",
                "--memory-budget",
                "16KiB",
                "--solver",
                "direct",
            ],
            vec!["paged.npy", "paged.json"],
            // The pager's backing file (the medium's and the fluence's bricks) is larger
            // than the fluence, so the disk fills there first.
            "its out-of-core storage failed",
        ),
    ];
    for (args, older, failing) in cases {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("tiny.toml"), &tiny).unwrap();
        for name in &older {
            std::fs::write(dir.path().join(name), b"an older file").unwrap();
        }
        let mut all = args.clone();
        all.push("-q");
        let out = lucent_on_a_full_disk(&all, dir.path(), 1);
        assert_clean_failure(&out, failing);
        for name in &older {
            assert_eq!(
                std::fs::read(dir.path().join(name)).unwrap(),
                b"an older file",
                "{args:?} touched {name}"
            );
        }
        let left: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains("partial") || n.starts_with(".lucent"))
            .collect();
        assert!(left.is_empty(), "{args:?} left {left:?}");
    }
}

/// Sends SIGINT to `child` after `after` and returns its output and how long it took to end
/// after the signal.
#[cfg(unix)]
fn interrupt_after(
    child: std::process::Child,
    after: std::time::Duration,
) -> (Output, std::time::Duration) {
    std::thread::sleep(after);
    let signalled = std::time::Instant::now();
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let out = child.wait_with_output().unwrap();
    (out, signalled.elapsed())
}

/// A cloud of `n`³ cells lit by a sun, as a scene file in `dir`.
fn cloud_scene(dir: &Path, n: usize) -> String {
    let text = std::fs::read_to_string(scene("default.toml"))
        .unwrap()
        .replace(
            "resolution = [64, 64, 64]",
            &format!("resolution = [{n}, {n}, {n}]"),
        );
    std::fs::write(dir.join("cloud.toml"), text).unwrap();
    "cloud.toml".into()
}

/// Ctrl-C before a solve has started (building a paged medium takes tens of seconds at
/// 384³) ends the process at once with 130, writing nothing; Ctrl-C during `resolution`
/// exits 130, not 3 (its interrupted level read as "did not converge").
#[cfg(unix)]
#[test]
fn ctrl_c_before_a_solve_or_during_resolution_exits_130_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let cloud = cloud_scene(dir.path(), 384);
    let child = Command::new(env!("CARGO_BIN_EXE_lucent"))
        .args([
            "solve",
            &cloud,
            "--solver",
            "direct",
            "--memory-budget",
            "64MiB",
        ])
        .args(["-o", "phi.npy", "-q"])
        .current_dir(dir.path())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let (out, took) = interrupt_after(child, std::time::Duration::from_millis(500));
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    assert!(took < std::time::Duration::from_secs(1), "took {took:?}");
    assert!(!dir.path().join("phi.npy").exists() && !dir.path().join("phi.json").exists());

    let cloud = cloud_scene(dir.path(), 96);
    let child = Command::new(env!("CARGO_BIN_EXE_lucent"))
        .args([
            "resolution",
            &cloud,
            "--solver",
            "diffusion-jacobi",
            "--error",
            "0.001",
        ])
        .current_dir(dir.path())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let (out, took) = interrupt_after(child, std::time::Duration::from_millis(1500));
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    assert!(took < std::time::Duration::from_secs(1), "took {took:?}");
}

/// `render --solver mc --time-limit` stops within a second of the limit (camera paths once
/// ignored it): a solve that did not finish, exit 3, no image unless
/// `--allow-unconverged`, which writes the rows traced.
#[test]
fn a_path_traced_render_honours_the_time_limit() {
    let dir = tempfile::tempdir().unwrap();
    let cloud = cloud_scene(dir.path(), 64);
    for (allow, code) in [(false, 3), (true, 0)] {
        let started = std::time::Instant::now();
        let mut args = vec![
            "render",
            &cloud,
            "--solver",
            "mc",
            "--param",
            "spp=65536",
            "--size",
            "64x48",
            "--time-limit",
            "1",
            "-o",
            "mc.png",
            "-q",
        ];
        if allow {
            args.push("--allow-unconverged");
        }
        let out = lucent(&args, dir.path());
        let took = started.elapsed();
        assert_eq!(out.status.code(), Some(code), "{}", stderr(&out));
        // One second of tracing, a second for the rest (building the scene, writing).
        assert!(took < std::time::Duration::from_secs(3), "took {took:?}");
        assert_eq!(dir.path().join("mc.png").exists(), allow);
    }
    // Without -q the summary gives the paths' time (it said "solve 0.00 s"): about the
    // one-second limit.
    let out = lucent(
        &[
            "render",
            &cloud,
            "--solver",
            "mc",
            "--param",
            "spp=65536",
            "--size",
            "64x48",
            "--time-limit",
            "1",
            "-o",
            "mc.png",
            "--allow-unconverged",
        ],
        dir.path(),
    );
    let said = String::from_utf8_lossy(&out.stdout);
    let seconds: f64 = said
        .split("(camera paths ")
        .nth(1)
        .and_then(|rest| rest.split(" s)").next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{said}"));
    assert!((0.8..3.0).contains(&seconds), "{said}");
}

/// A scene with a `data:` volume is found from any working folder (it resolved only from
/// the clone's root): without `$LUCENT_DATA`, the first `shared/data/volumes` beside the
/// scene's folder or a parent of it.
#[test]
fn data_volumes_resolve_from_any_working_folder() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let beside = root.join("../shared/data/volumes/tooth_103x94x161_uint8.raw");
    if !beside.is_file() {
        // The layout CI has (the data beside the clone); elsewhere there is nothing to find.
        eprintln!("skipped: no shared/data/volumes beside the clone");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_lucent"))
        .args(["info", &scene("ct_tooth.toml")])
        .current_dir(dir.path())
        .env_remove("LUCENT_DATA")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("103"),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
}

/// A scene needs no `[camera]` for `info` and `solve` (it was required, its error at line
/// 1, column 1), and `render` frames the box without one; a scene without `[solver]` runs
/// `direct` and, unless `--quiet`, says what that leaves out.
#[test]
fn a_scene_without_camera_or_solver_runs_and_says_what_direct_leaves_out() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("bare.toml"),
        "[volume]\nkind = \"blob\"\nresolution = [13, 10, 9]\nbounds = [[2.0, -1.0, 0.0], [4.0, 0.5, 1.2]]\ncentre = [3.0, -0.25, 0.6]\nsigma = 0.3\n\
         [medium]\ndensity = 30.0\nalbedo = 0.9\n\
         [[lights]]\nkind = \"directional\"\ndirection = [0.0, 0.0, -1.0]\nirradiance = 4.0\n",
    )
    .unwrap();
    let info = lucent(&["info", "bare.toml"], d);
    assert_eq!(info.status.code(), Some(0), "{}", stderr(&info));
    let solve = lucent(&["solve", "bare.toml", "-o", "phi.npy"], d);
    assert_eq!(solve.status.code(), Some(0), "{}", stderr(&solve));
    assert!(
        stderr(&solve).contains("has no [solver]"),
        "{}",
        stderr(&solve)
    );
    let quiet = lucent(&["solve", "bare.toml", "-o", "phi.npy", "-q"], d);
    assert!(stderr(&quiet).is_empty(), "{}", stderr(&quiet));
    let render = lucent(
        &[
            "render",
            "bare.toml",
            "-o",
            "bare.png",
            "--size",
            "64x48",
            "-q",
        ],
        d,
    );
    assert_eq!(render.status.code(), Some(0), "{}", stderr(&render));
    // The framing camera looks at the box's centre (far from the origin here): the lit
    // blob there stands out from the picture's corner.
    let image = image::open(d.join("bare.png")).unwrap().into_rgb8();
    let centre = i32::from(image.get_pixel(32, 24)[1]);
    let corner = i32::from(image.get_pixel(0, 0)[1]);
    assert!(
        (centre - corner).abs() > 8,
        "centre {centre}, corner {corner}"
    );
}

/// A procedural scene too large for the budget in memory is not called invalid: the
/// refusal says which command and which solvers solve it out of core (every solver that
/// pages, from the registry: the list was stale and `render`, whose solver was `direct`,
/// was told `direct` would do).
#[test]
fn a_scene_over_the_budget_in_memory_says_who_pages_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("big.toml"),
        "[volume]\nkind = \"cloud\"\nresolution = [100, 90, 70]\nbounds = [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]\nseed = 1\n\
         [medium]\ndensity = 10.0\nalbedo = 0.9\n\
         [[lights]]\nkind = \"directional\"\ndirection = [0.0, 0.0, -1.0]\nirradiance = 1.0\n",
    )
    .unwrap();
    for command in [
        &["render", "big.toml", "-o", "big.png"][..],
        &[
            "solve",
            "big.toml",
            "--solver",
            "diffusion-mg",
            "-o",
            "phi.npy",
        ][..],
    ] {
        let mut args = command.to_vec();
        args.extend_from_slice(&["--memory-budget", "8MiB"]);
        let out = lucent(&args, d);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(!err.contains("invalid scene"), "{err}");
        assert!(err.contains("over the memory budget"), "{err}");
        assert!(
            err.contains("`lucent solve` solves this procedural scene out of core"),
            "{err}"
        );
        for solver in lucent::scene::paging_solvers() {
            assert!(err.contains(&format!("`{solver}`")), "{solver}: {err}");
        }
    }
    let pagers = lucent::scene::paging_solvers();
    for solver in ["direct", "convection-diffusion", "mc", "ftcs-diffusion"] {
        assert!(pagers.iter().any(|p| p == solver), "{pagers:?}");
    }
    // `info` describes it from the paged medium: the same medium line as in memory (the
    // paged medium is evaluated with the same arithmetic; the mean is summed in another
    // order, which the printed digits do not see), and says who pages it.
    let medium_line = |args: &[&str]| {
        let out = lucent(args, d);
        assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        let line = text
            .lines()
            .find(|l| l.trim_start().starts_with("medium"))
            .unwrap_or_else(|| panic!("no medium line: {text}"))
            .to_owned();
        (line, text)
    };
    let (paged, text) = medium_line(&["info", "big.toml", "--memory-budget", "8MiB"]);
    let (in_memory, _) = medium_line(&["info", "big.toml"]);
    assert_eq!(paged, in_memory);
    assert!(text.contains("paged in bricks of"), "{text}");
    assert!(
        text.contains("`lucent render` needs the scene in memory"),
        "{text}"
    );
    assert!(
        text.contains("`direct`: `lucent solve` pages this scene"),
        "{text}"
    );
    let (_, text) = medium_line(&[
        "info",
        "big.toml",
        "--memory-budget",
        "8MiB",
        "--solver",
        "diffusion-mg",
    ]);
    assert!(
        text.contains("`lucent solve --solver NAME` pages it with"),
        "{text}"
    );
    // And `solve` with one of them does page it.
    let out = lucent(
        &[
            "solve",
            "big.toml",
            "--solver",
            "direct",
            "-o",
            "phi.npy",
            "-q",
            "--memory-budget",
            "8MiB",
        ],
        d,
    );
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
}
