"""The renderer from Python gives the command line's picture, and the diffusion system
is the matrix multigrid solves."""

import struct
import subprocess
import zlib

import numpy as np
import pytest

import lucent


def read_png(path):
    """An 8-bit RGB(A) PNG as (height, width, channels) uint8: enough of the format for
    the files lucent writes (every filter type undone)."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, chunks = 8, {}
    idat = b""
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos : pos + 8])
        body = data[pos + 8 : pos + 8 + length]
        pos += 12 + length
        if kind == b"IDAT":
            idat += body
        else:
            chunks[kind] = body
    width, height, depth, colour = struct.unpack(">IIBB", chunks[b"IHDR"][:10])
    assert depth == 8 and colour in (2, 6)
    channels = 3 if colour == 2 else 4
    raw = zlib.decompress(idat)
    stride = width * channels
    out = np.zeros((height, stride), dtype=np.int32)
    for y in range(height):
        line = np.frombuffer(raw, dtype=np.uint8, count=stride, offset=y * (stride + 1) + 1).astype(np.int32)
        kind = raw[y * (stride + 1)]
        prior = out[y - 1] if y else np.zeros(stride, dtype=np.int32)
        row = np.zeros(stride, dtype=np.int32)
        for x in range(stride):
            left = row[x - channels] if x >= channels else 0
            up = prior[x]
            corner = prior[x - channels] if x >= channels else 0
            if kind == 0:
                predictor = 0
            elif kind == 1:
                predictor = left
            elif kind == 2:
                predictor = up
            elif kind == 3:
                predictor = (left + up) // 2
            else:
                p = left + up - corner
                pa, pb, pc = abs(p - left), abs(p - up), abs(p - corner)
                predictor = left if pa <= pb and pa <= pc else (up if pb <= pc else corner)
            row[x] = (line[x] + predictor) & 0xFF
        out[y] = row
    return out.reshape(height, width, channels)[..., :3].astype(np.uint8)


@pytest.mark.parametrize("scene,solver", [("cloud", "dom"), ("ketchup_green", "diffusion-mg"), ("anisotropic", "mc")])
def test_render_equals_the_command_lines_png(root, lucent_bin, tmp_path, scene, solver):
    path = root / "examples" / "scenes" / "suite" / f"{scene}.toml"
    out = tmp_path / "image.png"
    params = ["--param", "spp=4"] if solver == "mc" else []
    subprocess.run(
        [str(lucent_bin), "render", str(path), "--solver", solver, "--size", "40x30", "-o", str(out), "--quiet", *params],
        check=True,
        capture_output=True,
    )
    kwargs = {"spp": 4} if solver == "mc" else {}
    rendering = lucent.render(lucent.Scene.load(path), solver, size=(40, 30), **kwargs)
    radiance = np.asarray(rendering)
    assert radiance.shape == (30, 40, 3) and radiance.dtype == np.float32
    assert np.isfinite(radiance).all() and radiance.max() > 0
    np.testing.assert_array_equal(rendering.srgb(), read_png(out))
    if solver == "mc":
        assert rendering.std_error.shape == (30, 40, 3) and rendering.solution is None
    else:
        assert rendering.solution.converged
        # Rendering a solution given is the same picture.
        again = lucent.render(lucent.Scene.load(path), solution=rendering.solution, size=(40, 30))
        np.testing.assert_array_equal(again.radiance, rendering.radiance)


def test_diffusion_system_is_what_multigrid_solves(root):
    """A φ = b from `DiffusionSystem`: multigrid's φ leaves a relative residual below its
    tolerance in a matrix-vector product done here in numpy, independent of lucent."""
    scene = lucent.Scene.load(root / "examples" / "scenes" / "suite" / "marble_sphere.toml")
    system = lucent.DiffusionSystem(scene.problem())
    data, indices, indptr, shape = system.matrix()
    b = system.rhs()
    assert shape[0] == shape[1] == len(b) == len(system.cells())
    phi, cycles, seconds = system.solve_multigrid(rtol=1e-9)
    rows = np.repeat(np.arange(shape[0]), np.diff(indptr))
    product = np.bincount(rows, weights=data * phi[indices], minlength=shape[0])
    assert np.linalg.norm(product - b) / np.linalg.norm(b) < 1e-8
    assert 1 <= cycles <= 30 and seconds > 0
    # Symmetric positive definite: the operator multigrid and CG assume.
    dense_check = np.zeros(shape[0])
    dense_check[: min(50, shape[0])] = 1.0
    upper = np.bincount(rows, weights=data * dense_check[indices], minlength=shape[0])
    columns = np.zeros(shape[0])
    np.add.at(columns, indices, data * dense_check[rows])
    np.testing.assert_allclose(upper, columns, rtol=1e-12, atol=1e-12)
