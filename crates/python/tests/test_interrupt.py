"""Long solves release the GIL and stop cleanly: from another thread through a `Cancel`
token, and on Ctrl-C with `TimeLimit`-like semantics (the result so far, no crash)."""

import os
import pathlib
import signal
import subprocess
import sys
import threading
import time

import lucent

ROOT = pathlib.Path(__file__).resolve().parents[3]
CLOUD = ROOT / "examples" / "scenes" / "suite" / "cloud.toml"


def never_converging(cancel=None, progress=None):
    """Jacobi with no tolerance and no iteration limit to speak of: runs until stopped."""
    return lucent.solve(
        lucent.Scene.load(CLOUD),
        "jacobi-diffusion",
        rtol=0.0,
        max_iterations=10**12,
        cancel=cancel,
        progress=progress,
    )


def test_a_solve_in_a_thread_stops_when_cancelled_and_leaves_the_gil_free():
    cancel = lucent.Cancel()
    result = {}
    worker = threading.Thread(target=lambda: result.update(solution=never_converging(cancel)))
    start = time.monotonic()
    worker.start()
    # The main thread keeps running Python while the solve runs: the GIL is released.
    spins = 0
    while time.monotonic() - start < 0.5:
        spins += 1
    assert worker.is_alive()
    cancel.set()
    worker.join(timeout=20)
    assert not worker.is_alive(), "the solve did not stop"
    solution = result["solution"]
    assert solution.interrupted and solution.stop_reason == "interrupted"
    assert not solution.converged
    assert solution.iterations > 0 and len(solution.residual_history) >= solution.iterations
    assert spins > 10_000
    # What was computed comes back: a finite, non-zero fluence.
    assert solution.fluence.max() > 0


def test_time_limit_stops_a_solve():
    solution = lucent.solve(
        lucent.Scene.load(CLOUD), "jacobi-diffusion", rtol=0.0, max_iterations=10**12, time_limit=0.3
    )
    assert solution.stop_reason == "time-limit"
    assert solution.wall_time_s < 5


def test_a_progress_callback_that_raises_stops_the_solve_and_raises():
    class Stop(Exception):
        pass

    calls = []

    def progress(stage, fraction, iteration, residual):
        calls.append((stage, fraction, iteration))
        if iteration >= 5:
            raise Stop("enough")

    try:
        never_converging(progress=progress)
    except Stop:
        pass
    else:
        raise AssertionError("the callback's exception was swallowed")
    assert any(i >= 5 for _, _, i in calls)


def test_ctrl_c_stops_the_solve_and_returns_what_was_computed():
    # Python turns SIGINT into KeyboardInterrupt only where it was not ignored at start,
    # and a shell's background jobs (CI under nohup) start with it ignored: install the
    # handler an interactive session has.
    script = f"""
import signal, sys, lucent
signal.signal(signal.SIGINT, signal.default_int_handler)
sys.path.insert(0, {str(pathlib.Path(__file__).parent)!r})
from test_interrupt import never_converging
started = []
def progress(stage, fraction, iteration, residual):
    if iteration and not started:
        started.append(1)
        print("started", flush=True)
solution = never_converging(progress=progress)
print(solution.stop_reason, solution.iterations > 0, solution.fluence.max() > 0, flush=True)
"""
    child = subprocess.Popen(
        [sys.executable, "-c", script],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ},
    )
    try:
        assert child.stdout.readline().strip() == "started"
        time.sleep(0.3)
        child.send_signal(signal.SIGINT)
        out, err = child.communicate(timeout=30)
    finally:
        child.kill()
    assert child.returncode == 0, err
    assert out.strip() == "interrupted True True", (out, err)
