"""Files from Python appear whole or not at all: onto a full disk, write_volume raises
OSError, leaves the older file at the target and no partial file.

A full disk is simulated with the file-size limit (RLIMIT_FSIZE) in a fresh interpreter:
past it a write fails with EFBIG, partway through the file, as on a full file system."""

import subprocess
import sys
import textwrap

import pytest

FORMATS = ["npy", "vol", "nrrd", "mhd", "vtk", "vti"]


@pytest.mark.parametrize("extension", FORMATS)
def test_a_write_onto_a_full_disk_raises_and_keeps_the_older_file(tmp_path, extension):
    target = tmp_path / f"out.{extension}"
    target.write_bytes(b"an older file")
    code = textwrap.dedent(
        f"""
        import resource, signal, sys
        import numpy as np, lucent
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        data = np.arange(40 * 36 * 32, dtype=np.float32).reshape(32, 36, 40)
        write = lambda: lucent.write_volume({str(target)!r}, data)
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))
        try:
            write()
        except OSError as e:
            print("raised", e)
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("raised"), done.stdout + done.stderr[-2000:]
    assert target.read_bytes() == b"an older file"
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]
