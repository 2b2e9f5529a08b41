"""Shared fixtures: the repository, the `lucent` command-line binary (the Rust API's
results to compare against) and the shared test volumes."""

import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def root() -> pathlib.Path:
    return ROOT


@pytest.fixture(scope="session")
def lucent_bin() -> pathlib.Path:
    """`$LUCENT_BIN`, else the workspace's `lucent` built now (dev profile, whose
    numeric crates are optimised like release: the same bits, checked below)."""
    given = os.environ.get("LUCENT_BIN")
    if given:
        return pathlib.Path(given)
    subprocess.run(
        ["cargo", "build", "--quiet", "--bin", "lucent"], cwd=ROOT, check=True
    )
    return ROOT / "target" / "debug" / "lucent"


@pytest.fixture(scope="session")
def data_dir() -> pathlib.Path:
    """The shared volumes: `$LUCENT_DATA` (then a missing file fails the test), else
    `../shared/data/volumes` beside the repository (skipped where absent)."""
    given = os.environ.get("LUCENT_DATA")
    if given:
        return pathlib.Path(given)
    default = ROOT.parent / "shared" / "data" / "volumes"
    if not default.is_dir():
        pytest.skip("no shared test volumes (set LUCENT_DATA)")
    return default
