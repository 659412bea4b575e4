"""Fuzzing what a user or a file hands the viewer besides the scene files (tests/test_hostile_input.py has
those): the sidecar JSON, the baked-grid reader and the command line's numbers (sizes, cameras, the GI
flags). Any input is accepted, or refused with one line (exit status 2 on the command line); never another
exception, a numpy warning on the terminal, or a hang."""

import contextlib
import io
import json
import tempfile
import warnings
from pathlib import Path
from unittest import mock

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from baked_files import rewritten

from viewer import cli
from viewer.bake import grid as baked
from viewer.cli_parsing import gi_settings
from viewer.errors import exit_status
from viewer.physical import work
from viewer.probes.grid import ProbeGrid
from viewer.scene import SceneError, load

FUZZ = settings(max_examples=60, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


@contextlib.contextmanager
def no_numpy_warnings():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        yield
    assert not [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]


def one_line(exc: Exception) -> None:
    message = str(exc)
    assert message and "\n" not in message and len(message) < 600, message


# ---- the sidecar JSON ---------------------------------------------------------------------------------------

NUMBERS = (st.floats() | st.integers(-10**400, 10**400) | st.sampled_from([1e308, -1e308, 3.5e38, 1e-320, 0, -0.0])
           | st.text(max_size=4) | st.none() | st.booleans())
VECTORS = st.lists(NUMBERS, max_size=5) | NUMBERS
JSON = st.recursive(NUMBERS, lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner,
                                                                                           max_size=4), max_leaves=12)
SIDECARS = st.one_of(
    JSON,
    st.fixed_dictionaries({}, optional={
        "sun": st.fixed_dictionaries({}, optional={"direction": VECTORS, "irradiance": VECTORS}) | JSON,
        "camera": st.fixed_dictionaries({}, optional={"origin": VECTORS, "target": VECTORS, "up": VECTORS,
                                                      "fov": NUMBERS}) | JSON}))


@FUZZ
@given(SIDECARS)
def test_any_sidecar_loads_or_is_refused_in_one_line(sidecar):
    text = json.dumps(sidecar, allow_nan=True) if not isinstance(sidecar, int) or abs(sidecar) < 10**300 else "1e999"
    with tempfile.TemporaryDirectory() as folder, no_numpy_warnings():
        (Path(folder) / "room.obj").write_text(TRIANGLE)
        (Path(folder) / "room.json").write_text(text)
        try:
            scene = load(Path(folder) / "room.obj")
        except SceneError as exc:
            one_line(exc)
            return
    assert np.isfinite(scene.vertices).all()
    if scene.sun is not None:
        assert np.isfinite(scene.sun.direction).all() and np.isfinite(scene.sun.irradiance).all()
    if scene.camera is not None:
        assert all(np.isfinite(v).all() for v in (scene.camera.origin, scene.camera.target, scene.camera.up))


# ---- the baked-grid reader ----------------------------------------------------------------------------------

ARRAYS = st.one_of(
    st.sampled_from([np.float64(np.nan), np.full(3, 1e308), np.full(3, -1e308), np.int64(2**62), np.int64(-1),
                     np.int64(0), np.int64(129), np.zeros((0,)), np.array("text"), np.array(b"bytes"),
                     np.zeros((2, 2, 2, 9, 3), np.float16), np.full((2, 2, 2, 9, 3), 3e38, np.float32),
                     np.full((2, 2, 2, 9, 3), np.inf, np.float32), np.zeros((2, 2, 2), np.int8),
                     np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]), np.zeros(6), np.array("{" * 5000),
                     np.array(json.dumps({"a": [1] * 10})), np.array("../../../etc/passwd.obj"),
                     np.array("cornell"), np.array(""), np.array("x\x1b[31m.obj"), np.int32(2), np.bool_(True)]),
    st.lists(st.floats(width=32), min_size=0, max_size=8).map(lambda v: np.array(v, np.float32)),
    st.integers(-2**63, 2**63 - 1).map(np.int64))


@FUZZ
@given(st.dictionaries(st.sampled_from(baked.KEYS), ARRAYS | st.none(), max_size=4), st.integers(0, 2000),
       st.binary(min_size=0, max_size=4))
def test_any_baked_grid_reads_or_is_refused_in_one_line(changes, flip_at, flip):
    with tempfile.TemporaryDirectory() as folder, no_numpy_warnings():
        path = Path(folder) / "g.npz"
        grid = ProbeGrid(np.zeros(3), np.ones(3), np.ones((2, 2, 2, 9, 3), np.float32), np.ones((2, 2, 2), bool))
        baked.write_npz(baked.BakedGrid(grid, grid, "cornell", None, {"voxels": 8}), path)
        rewritten(path, path, compressed=True, **changes)
        if flip:   # bytes of the archive itself overwritten
            data = bytearray(path.read_bytes())
            at = flip_at % max(len(data), 1)
            data[at:at + len(flip)] = flip
            path.write_bytes(bytes(data))
        try:
            grid = baked.read_npz(path)
            source = baked.scene_source(grid, path)
        except baked.BakedError as exc:
            one_line(exc)
            return
    assert grid.radiance.resolution <= work.MAX_PROBES and np.isfinite(grid.radiance.coefficients).all()
    assert isinstance(source, str)


# ---- the command line's numbers -----------------------------------------------------------------------------

TEXT_NUMBERS = st.one_of(
    st.integers(-2**70, 2**70).map(str), st.floats().map(repr),
    st.sampled_from(["nan", "inf", "-inf", "1e309", "", "0x10", "1_0", "٣", " 4", "4 ", "1e-320", "-0", "1e15",
                     "1e16", "3.5e38"]))
SIZES = st.one_of(st.tuples(TEXT_NUMBERS, TEXT_NUMBERS).map("x".join), TEXT_NUMBERS,
                  st.sampled_from(["8192x8192", "8193x1", "1x1", "0x0", "-1x5", "16384x16384", "64x64"]))
CAMERAS = st.one_of(st.lists(TEXT_NUMBERS, min_size=0, max_size=7).map(",".join),
                    st.sampled_from(["0,0,0,0,0,0", "1e30,0,0,0,0,0", "0,0,1,0,0,0", "nan,0,0,0,0,1"]))
GI_FLAGS = ("--voxels", "--probes", "--bounces", "--directions", "--gather-rays", "--dering",
            "--invalid-backface-fraction")
RENDER_FLAGS = ("--fov", "--exposure", "--msaa", "--light-samples")


def flags(names, values):
    return st.dictionaries(st.sampled_from(names), values, max_size=len(names)).map(
        lambda chosen: [f"{name}={value}" for name, value in chosen.items()])


def command_status(command) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), no_numpy_warnings():
        status = exit_status(command)
    return status, err.getvalue()


@FUZZ
@given(st.sampled_from(["sample", "bake", "view"]), flags(GI_FLAGS, TEXT_NUMBERS), SIZES)
def test_any_gi_flags_are_accepted_within_the_limit_or_refused_in_one_line(command, gi, size):
    args = {"sample": ["sample", "cornell", "--points", "p.npy", "--out", "o.npy"],
            "bake": ["bake", "cornell", "--out", "o.npz"], "view": ["view", "cornell", f"--size={size}"]}[command]
    chosen = {}

    def parse() -> int:
        from viewer.cli_parsing import parse_size

        parsed = cli.build_parser().parse_args(args + gi)
        window = parse_size(parsed.size) if command == "view" else None
        chosen["settings"] = gi_settings(parsed, size=window)
        return 0

    status, err = command_status(parse)
    assert status in (0, 2), err
    if status == 2:
        assert err.count("\n") == 1 and err.startswith("error:"), err
    else:
        work.check_work(chosen["settings"])


@FUZZ
@given(flags(GI_FLAGS + RENDER_FLAGS, TEXT_NUMBERS), SIZES, CAMERAS | st.none())
def test_any_capture_numbers_render_or_are_refused_in_one_line(numbers, size, camera):
    """`capture --gi off` up to the renderer (which is replaced here): the request is checked and the scene
    loaded, then either a picture is asked for or one line says why not."""
    args = ["capture", "cornell", "--out", str(Path(tempfile.gettempdir()) / "fuzz.png"), "--gi", "off",
            f"--size={size}", *numbers] + ([f"--camera={camera}"] if camera is not None else [])
    drawn = []
    context = mock.MagicMock()
    with mock.patch("viewer.gpu.context.create_context", return_value=context), \
            mock.patch("viewer.gpu.offscreen.capture", side_effect=lambda *a, **k: drawn.append(k)):
        status, err = command_status(lambda: cli.run_command(cli.build_parser().parse_args(args)))
    assert status in (0, 2), err
    lines = err.splitlines()
    if status == 2:
        assert len(lines) == 1 and lines[0].startswith("error:"), err
    else:
        assert len(drawn) == 1 and lines[-1].startswith("capture:"), err
        camera = drawn[0]["camera"]
        assert all(np.isfinite(v).all() for v in (camera.origin, camera.target, camera.up))
