"""The same sparse system as lucent-diffusion's multigrid, solved by pyamg and scipy.

Usage: python3 pyamg_bench.py DIR, where DIR holds indptr.npy, indices.npy, data.npy (the
CSR operator over the medium's cells), rhs.npy and lucent.npy (lucent's solution), as
written by `cargo xtask bench-diffusion`. Prints one line per solver: setup and solve
seconds, iterations, the relative residual reached, and the relative L2 difference from
lucent's solution (the same discrete system, so it measures the solvers, not a model).
"""

import sys
import time

import numpy as np
import pyamg
import scipy
import scipy.sparse
import scipy.sparse.linalg


def main(directory):
    load = lambda name: np.load(f"{directory}/{name}.npy")
    a = scipy.sparse.csr_matrix((load("data"), load("indices"), load("indptr")))
    b, ours = load("rhs"), load("lucent")
    norm_b = np.linalg.norm(b)

    def report(name, setup, solve, iterations, x):
        residual = np.linalg.norm(b - a @ x) / norm_b
        difference = np.linalg.norm(x - ours) / np.linalg.norm(ours)
        print(
            f"{name}: setup {setup:.2f} s, solve {solve:.2f} s, total {setup + solve:.2f} s, "
            f"{iterations} iterations, relative residual {residual:.1e}, "
            f"difference from lucent {difference:.1e}"
        )

    print(f"{a.shape[0]} unknowns, {a.nnz} non-zeros, pyamg {pyamg.__version__}, scipy {scipy.__version__}")
    started = time.perf_counter()
    ml = pyamg.ruge_stuben_solver(a)
    setup = time.perf_counter() - started
    residuals = []
    started = time.perf_counter()
    x = ml.solve(b, tol=1e-8, accel="cg", maxiter=500, residuals=residuals)
    report("  pyamg Ruge–Stüben + CG", setup, time.perf_counter() - started, len(residuals) - 1, x)

    count = [0]
    started = time.perf_counter()
    x, _ = scipy.sparse.linalg.cg(
        a, b, rtol=1e-8, maxiter=20000, callback=lambda _: count.__setitem__(0, count[0] + 1)
    )
    report("  scipy CG (no preconditioner)", 0.0, time.perf_counter() - started, count[0], x)


if __name__ == "__main__":
    main(sys.argv[1])
