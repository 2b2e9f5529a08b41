"""One pareto chart and one stability map, from Python, in a notebook's order.

    python examples/python/pareto_and_stability.py [--out DIR] [--scene NAME]

1. **Error against time** on a suite scene (default `thin_smoke`): every solver family at
   a few settings, each solve's relative L2 error over the medium against a Monte Carlo
   reference of the total fluence (so `direct`, the uncollided light alone, and the
   diffusion solvers level off at their models' errors), plotted against its wall time: the chart `cargo xtask pareto` draws into
   docs/pareto/, here in twenty lines of numpy.
2. **Where FTCS diffusion blows up**: Murray's explicit scheme on a homogeneous
   reflecting box, run at step fractions around its von Neumann bound, over β = D/Δ; each
   run marked stable or diverged, with the thesis's bound (Eq. 4.9), von Neumann's and
   positivity's drawn from `lucent.stability`.

Needs matplotlib (`pip install matplotlib`); writes `pareto.png` and `stability.png`.
"""

import argparse
import pathlib
import time

import numpy as np

import lucent

ROOT = pathlib.Path(__file__).resolve().parents[2]

# --- 1. Error against time ------------------------------------------------------------

# (solver, parameters, rtol): each family over the knob that trades time for accuracy.
RUNS = [
    ("direct", {"sky_level": 0}, None),
    ("diffusion-mg", {}, 1e-2),
    ("diffusion-mg", {}, 1e-6),
    ("diffusion-cg", {}, 1e-4),
    ("fem-diffusion", {}, 1e-6),
    ("dom", {"order": 2}, 1e-4),
    ("dom", {"order": 4}, 1e-4),
    ("dom", {"order": 8}, 1e-4),
    ("lbm", {}, 1e-5),
    ("hybrid", {"orders": 1}, 1e-4),
    ("hybrid", {"orders": 4}, 1e-4),
    ("convection-diffusion", {}, 1e-5),
    ("mc", {"particles": 2_000, "batches": 8}, None),
    ("mc", {"particles": 20_000, "batches": 8}, None),
]


def relative_l2(ours, reference, mask):
    """‖ours − reference‖ / ‖reference‖ over the masked cells, all channels."""
    d = (ours - reference)[:, mask]
    return float(np.sqrt((d.astype(np.float64) ** 2).sum() / (reference[:, mask].astype(np.float64) ** 2).sum()))


def pareto(scene_name, out):
    scene = lucent.Scene.load(ROOT / "examples" / "scenes" / "suite" / f"{scene_name}.toml")
    problem = scene.problem()
    print(f"{scene_name}: {problem}")
    start = time.time()
    reference = lucent.solve(problem, "mc", particles=1_000_000, batches=16, seed=7)
    noise = reference.report["stop_reason"]["relative_error"]
    print(f"reference: Monte Carlo, mean relative standard error {noise:.2%}, {time.time() - start:.1f} s")
    mask = problem.sigma_t.max(axis=0) > 0  # the medium's cells
    points = []
    for solver, params, rtol in RUNS:
        try:
            solution = lucent.solve(problem, solver, rtol=rtol, **params)
        except lucent.UnsupportedError as e:
            print(f"  {solver:22s} refuses: {e}")
            continue
        error = relative_l2(solution.fluence, reference.fluence, mask)
        label = solver + "".join(f" {k}={v}" for k, v in params.items()) + (f" rtol={rtol:.0e}" if rtol else "")
        points.append((solver, label, solution.wall_time_s, error))
        print(f"  {label:34s} {solution.wall_time_s * 1e3:9.2f} ms  error {error:7.2%}  ({solution.stop_reason})")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    families = sorted({p[0] for p in points})
    colours = dict(zip(families, plt.cm.tab10(np.linspace(0, 1, max(len(families), 2)))))
    for solver, label, seconds, error in points:
        ax.scatter(seconds, error, color=colours[solver], s=30)
        ax.annotate(label, (seconds, error), fontsize=6, xytext=(3, 3), textcoords="offset points")
    # The pareto front: no other run is both faster and more accurate.
    front = sorted(points, key=lambda p: p[2])
    best, frontier = np.inf, []
    for p in front:
        if p[3] < best:
            best = p[3]
            frontier.append(p)
    ax.step([p[2] for p in frontier], [p[3] for p in frontier], where="post", color="k", lw=0.8)
    ax.axhline(noise, color="grey", ls=":", lw=0.8, label="reference's standard error")
    ax.set(xscale="log", yscale="log", xlabel="wall time (s)", ylabel="relative L2 error of the fluence",
           title=f"{scene_name}: error against time (2-core CPU)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "pareto.png", dpi=150)
    print(f"wrote {out / 'pareto.png'}")


# --- 2. The stability map -------------------------------------------------------------


def ftcs_run(beta, albedo, fraction, n=10):
    """FTCS diffusion on an n³ reflecting box of β = D/Δ and `albedo`, at `fraction` of
    its step bound (on a homogeneous medium with zero-flux faces the solver's bound,
    Gershgorin's on the assembled rows, is von Neumann's): did it diverge?"""
    h = 1.0 / n
    sigma_t = 1.0 / (3.0 * beta * h)  # β = D/h with D = 1/(3σ_t) (g = 0)
    problem = lucent.Problem(
        np.full((n, n, n), sigma_t, dtype=np.float32),
        albedo,
        spacing=h,
        boundary={"kind": "neumann", "flux": 0.0},
        lights=[{"kind": "point", "position": [0.5, 0.5, 0.5], "intensity": 1.0}],
    )
    solution = lucent.solve(
        problem, "ftcs-diffusion", step_fraction=fraction, allow_unstable=True, rtol=1e-10, max_iterations=600
    )
    return solution.diverged


def stability(out, albedo=0.9):
    betas = np.geomspace(0.05, 1.0, 9)
    fractions = np.linspace(0.3, 1.3, 11)
    diverged = np.array([[ftcs_run(b, albedo, f) for b in betas] for f in fractions])
    vn = lucent.stability.ftcs_diffusion.von_neumann(betas, albedo)
    murray = lucent.stability.ftcs_diffusion.murray(betas, albedo) / vn
    positivity = lucent.stability.ftcs_diffusion.positivity(betas, albedo) / vn
    first = [fractions[np.argmax(diverged[:, j])] if diverged[:, j].any() else np.nan for j in range(len(betas))]
    print(f"FTCS diffusion, albedo {albedo}: first diverged step fraction per β = {np.round(first, 2)}")
    print(f"Murray's Eq. 4.9 over β = {betas[0]:.2f}..{betas[-1]:.2f}: {murray.min():.2f}–{murray.max():.2f} of the von Neumann bound")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.5))
    B, F = np.meshgrid(betas, fractions)
    ax.scatter(B[~diverged], F[~diverged], marker="o", s=18, color="tab:blue", label="stable")
    ax.scatter(B[diverged], F[diverged], marker="x", s=22, color="tab:red", label="diverged")
    ax.plot(betas, np.ones_like(betas), "k-", lw=1, label="von Neumann")
    ax.plot(betas, murray, "k--", lw=1, label="Murray Eq. 4.9 (thesis)")
    ax.plot(betas, positivity, "k:", lw=1, label="positivity")
    ax.set(xscale="log", xlabel="β = D/Δ", ylabel="cΔt / von Neumann bound",
           title=f"FTCS diffusion: where it blows up (albedo {albedo})")
    ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(out / "stability.png", dpi=150)
    print(f"wrote {out / 'stability.png'}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("."))
    parser.add_argument("--scene", default="thin_smoke")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    pareto(args.scene, args.out)
    stability(args.out)
