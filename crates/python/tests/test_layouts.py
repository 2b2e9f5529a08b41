"""Arrays in any memory layout give the C-order copy's answer bit for bit (or a
ValueError naming the layout), and no input ends the interpreter.

numpy hands lucent views as they lie in memory: a Fortran-order copy, a transposed or
strided view, a broadcast with zero strides. lucent reads a grid as a[z, y, x]; reading
the memory in its own order instead turned z layers into x layers without a word (the
fluence differed by up to 100 %)."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest

import lucent

SHAPE = (5, 6, 7)  # (n_z, n_y, n_x): three different sides, so a transposition shows.


def field(seed=0, low=0.5, high=4.0):
    rng = np.random.default_rng(seed)
    return rng.uniform(low, high, SHAPE).astype(np.float32)


def layouts(a):
    """`a` (C order) in every layout numpy makes, each equal to `a` by index."""
    big = np.zeros((SHAPE[0] * 2, SHAPE[1] * 3, SHAPE[2] * 2), a.dtype)
    big[::2, ::3, ::2] = a
    yield "C", a
    yield "Fortran", np.asfortranarray(a)
    yield "transposed twice", np.ascontiguousarray(a.transpose(2, 1, 0)).transpose(2, 1, 0)
    yield "strided", big[::2, ::3, ::2]
    yield "reversed", np.ascontiguousarray(a[::-1, :, ::-1])[::-1, :, ::-1]
    yield "float64 Fortran", np.asfortranarray(a.astype(np.float64))
    yield "float16 strided", big.astype(np.float16)[::2, ::3, ::2]


def bits(a):
    return np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)


PROBLEM = {
    "lights": [{"kind": "directional", "direction": [0.3, -0.2, -0.93], "irradiance": 1.0}],
    "spacing": (0.1, 0.1, 0.1),
}


def solve(sigma_t, albedo, emission=None):
    lights = list(PROBLEM["lights"])
    if emission is not None:
        lights.append({"kind": "emission", "scale": 1.0})
    problem = lucent.Problem(
        sigma_t, albedo, spacing=PROBLEM["spacing"], lights=lights, emission=emission
    )
    return lucent.solve(problem, "diffusion-mg").fluence


def test_every_layout_of_every_field_gives_the_c_order_answer():
    sigma_t, albedo = field(1), field(2, 0.1, 0.9)
    emission = field(3, 0.0, 1.0)
    reference = solve(sigma_t, albedo, emission)
    # A z layer read as an x layer would change the answer: the reference is not blind.
    swapped = np.ascontiguousarray(sigma_t.transpose(2, 1, 0)).reshape(SHAPE)
    assert not np.array_equal(bits(reference), bits(solve(swapped, albedo, emission)))
    for name, a in layouts(sigma_t):
        expected = reference if a.dtype != np.float16 else solve(a.astype(np.float32), albedo, emission)
        got = solve(a, albedo, emission)
        assert np.array_equal(bits(got), bits(expected)), f"sigma_t {name}"
    for name, a in layouts(albedo):
        if a.dtype == np.float16:
            continue
        assert np.array_equal(bits(solve(sigma_t, a, emission)), bits(reference)), f"albedo {name}"
    for name, a in layouts(emission):
        if a.dtype == np.float16:
            continue
        assert np.array_equal(bits(solve(sigma_t, albedo, a)), bits(reference)), f"emission {name}"


def test_a_broadcast_array_reads_as_its_values():
    row = np.linspace(0.5, 3.0, SHAPE[2], dtype=np.float32)
    broadcast = np.broadcast_to(row, SHAPE)
    assert broadcast.strides[0] == 0
    albedo = field(2, 0.1, 0.9)
    assert np.array_equal(
        bits(solve(broadcast, albedo)), bits(solve(np.array(broadcast), albedo))
    )


def test_a_zero_size_array_is_a_value_error():
    with pytest.raises(ValueError, match="empty axis"):
        lucent.Problem(np.ones((0, 6, 7), np.float32))
    with pytest.raises(ValueError, match="empty axis"):
        lucent.Problem(np.asfortranarray(np.ones((5, 0, 7), np.float32)))


def test_an_embedded_body_in_any_layout():
    z, y, x = np.meshgrid(*(np.arange(n) + 0.5 for n in SHAPE), indexing="ij")
    sdf = (np.sqrt((x - 3.5) ** 2 + (y - 3) ** 2 + (z - 2.5) ** 2) - 2.2).astype(np.float32) * 0.1
    sigma = field(1)

    def embedded(body):
        return lucent.Problem(sigma, 0.8, spacing=0.1, embedded=body).embedded

    reference = embedded(sdf)
    assert np.array_equal(bits(reference), bits(sdf))
    for name, a in layouts(sdf):
        if a.dtype == np.float16:
            continue
        assert np.array_equal(bits(embedded(a)), bits(reference)), name


@pytest.mark.parametrize("extension", ["npy", "vol", "nrrd", "mhd", "vtk", "vti"])
def test_write_volume_writes_the_array_by_index(tmp_path, extension):
    data = field(4)
    for name, a in layouts(data):
        if a.dtype == np.float16:
            continue
        path = tmp_path / f"{name.replace(' ', '_')}.{extension}"
        lucent.write_volume(path, a, spacing=0.5)
        back = lucent.read_volume(path).data
        assert np.array_equal(bits(back), bits(data)), f"{extension} {name}"


def run_isolated(code):
    """`code` in a fresh interpreter; its exit status and output. A crash (segfault,
    abort, out of memory) shows as a status that is not 0."""
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=120,
    )


# Each case must raise the named exception inside the interpreter, which then exits 0.
KILLERS = [
    # 32 GB of f32 from a broadcast view that costs numpy nothing.
    (
        "broadcast 2000^3",
        "lucent.Problem(np.broadcast_to(np.float32(1), (2000,) * 3), 0.5)",
        "MemoryError",
    ),
    (
        "broadcast 2000^3 as write_volume data",
        "lucent.write_volume(tmp + '/big.npy', np.broadcast_to(np.float32(1), (2000,) * 3))",
        "MemoryError",
    ),
    (
        "broadcast under a small budget",
        "lucent.Problem(np.broadcast_to(np.float32(1), (256,) * 3), 0.5, memory_budget=1 << 20)",
        "MemoryError",
    ),
    (
        "a dict nested 20 000 deep",
        "d = {}\nx = d\nfor _ in range(20000):\n    x['a'] = {}\n    x = x['a']\nlucent.Scene.from_dict(d)",
        "ValueError",
    ),
    (
        "a list that holds itself",
        "l = []\nl.append(l)\nlucent.Scene.from_dict({'volume': l})",
        "ValueError",
    ),
    (
        "lights nested 100 000 deep",
        "x = {}\nfor _ in range(100000):\n    x = [x]\nlucent.Problem(np.ones((2, 2, 2), np.float32), lights=x)",
        "ValueError",
    ),
]


@pytest.mark.parametrize("name,call,exception", KILLERS, ids=[k[0] for k in KILLERS])
def test_no_input_ends_the_interpreter(tmp_path, name, call, exception):
    code = f"""
import numpy as np, lucent
tmp = {str(tmp_path)!r}
try:
{textwrap.indent(call, '    ')}
except {exception} as e:
    print('raised', type(e).__name__, str(e)[:200])
else:
    print('accepted')
"""
    done = run_isolated(code)
    assert done.returncode == 0, f"{name}: exit {done.returncode}\n{done.stderr[-2000:]}"
    assert done.stdout.startswith("raised"), f"{name}: {done.stdout}{done.stderr[-2000:]}"


def test_read_volume_refuses_a_bomb_under_the_default_budget(tmp_path):
    """A 1 MB gzip NRRD that claims 1024^3 float32 (4 GiB): the command line refuses it
    from the header, and so must read_volume (its default budget is the command line's).
    Run in a subprocess: inflating it would take 4 GiB."""
    import gzip

    payload = gzip.compress(b"\0" * (1 << 20))
    header = (
        "NRRD0004\ntype: float\ndimension: 3\nsizes: 1024 1024 1024\nencoding: gzip\n\n"
    )
    path = tmp_path / "bomb.nrrd"
    path.write_bytes(header.encode() + payload)
    done = run_isolated(
        f"""
import lucent
try:
    lucent.read_volume({str(path)!r})
except MemoryError as e:
    print('raised', e)
"""
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("raised") and "budget" in done.stdout, done.stdout


def test_render_refuses_the_solution_of_another_problem(root):
    scene = lucent.Scene.load(root / "examples" / "scenes" / "suite" / "slab.toml")
    other = lucent.Scene.load(root / "examples" / "scenes" / "suite" / "thin_smoke.toml")
    solution = lucent.solve(other, "direct")
    with pytest.raises(ValueError, match="another problem"):
        lucent.render(scene, solution=solution, size=(8, 6))
    # Its own solution renders.
    own = lucent.solve(scene, "direct")
    assert lucent.render(scene, solution=own, size=(8, 6)).rows_traced == 6
