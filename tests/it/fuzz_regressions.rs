//! The committed regression corpus (`fuzz/regressions/<target>/`): every input that ever
//! crashed, hung, aborted or let a non-finite value through a reader or a scene build, kept
//! small, replayed on stable by `cargo test`. Each must now be refused with an error, fast.
//! New findings of `cargo xtask fuzz` or `cargo fuzz` go into the folder of their target.

use std::time::{Duration, Instant};

use lucent::fuzzing::{Target, run};

#[test]
fn every_regression_input_is_refused_quickly() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/regressions");
    let mut replayed = 0;
    for target in Target::ALL {
        let Ok(entries) = std::fs::read_dir(root.join(target.name())) else {
            continue;
        };
        for entry in entries {
            let path = entry.unwrap().path();
            let bytes = std::fs::read(&path).unwrap();
            let started = Instant::now();
            let outcome = run(target, &bytes);
            assert!(
                started.elapsed() < Duration::from_secs(2),
                "{}: {:?}",
                path.display(),
                started.elapsed()
            );
            assert!(outcome.is_err(), "{} was accepted", path.display());
            replayed += 1;
        }
    }
    // The corpus is committed: an empty replay means the folder went missing.
    assert!(replayed >= 15, "replayed {replayed} inputs");
}
