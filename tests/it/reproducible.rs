//! A solve gives the same bits on every run and every thread count: its fluence, and its
//! residual history (the norms behind every stopping decision). Rayon's `sum()` over a
//! parallel iterator adds in an order its work stealing picks, so the Krylov solvers'
//! inner products and the multigrid's norms once differed in the last bits between runs
//! and pools; `lucent_core::reduce` fixes the order.

use std::path::Path;

use lucent::core::{Solution, SolveOptions};

fn solve(name: &str, problem: &lucent::core::Problem, threads: usize) -> Solution {
    let solver = lucent::registry()
        .build(name, &Default::default())
        .expect("a registered solver");
    let options = SolveOptions {
        relative_tolerance: 1e-8,
        threads: Some(threads),
        ..SolveOptions::default()
    };
    solver.solve(problem, &options).expect("it solves")
}

/// The Krylov and multigrid solvers on the marble sphere: 32³ cells, enough that the
/// pools split every vector.
#[test]
fn solves_are_the_same_bits_on_one_two_and_three_threads() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes/suite");
    let cases = [
        ("marble_sphere.toml", "diffusion-cg"),
        ("marble_sphere.toml", "diffusion-mgcg"),
        ("marble_sphere.toml", "diffusion-mg"),
        ("marble_sphere.toml", "fem-diffusion"),
    ];
    for (scene, name) in cases {
        let path = root.join(scene);
        let problem = lucent::scene::Scene::load(&path)
            .and_then(|s| s.build(&root))
            .expect("the suite scene builds")
            .problem;
        let reference = solve(name, &problem, 1);
        assert!(reference.report.stop_reason.is_converged(), "{name}");
        for threads in [2, 3, 2] {
            let other = solve(name, &problem, threads);
            let bits = |s: &Solution| -> Vec<u32> {
                s.fluence
                    .iter()
                    .flat_map(|g| g.data().iter().map(|v| v.to_bits()))
                    .collect()
            };
            assert!(
                bits(&other) == bits(&reference),
                "{name} on {scene}: fluence differs on {threads} threads"
            );
            let history = |s: &Solution| -> Vec<u64> {
                s.report
                    .residual_history
                    .iter()
                    .map(|r| r.to_bits())
                    .collect()
            };
            assert_eq!(
                history(&other),
                history(&reference),
                "{name} on {scene}: residual history differs on {threads} threads"
            );
        }
    }
}
