"""`python -m viewer sample`: the contract the evaluation tools rely on (docs/ARCHITECTURE.md, "Command
line")."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "viewer", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or ROOT, timeout=600)


@pytest.fixture
def points(tmp_path):
    path = tmp_path / "points.npy"
    np.save(path, np.array([[0.0, 0.0, 0.0], [0.5, -0.5, 0.2], [-0.6, 0.6, -0.3]], np.float32))
    return path


def test_sample_writes_sh_at_points_and_reports_seconds(tmp_path, points):
    out = tmp_path / "sh.npy"
    result = run("sample", "cornell", "--points", points, "--method", "solver", "--out", out,
                 "--voxels", "12", "--probes", "6", "--directions", "128")
    assert result.returncode == 0, result.stderr
    sh = np.load(out)
    assert sh.shape == (3, 9, 3) and sh.dtype == np.float32 and np.all(np.isfinite(sh))
    assert np.all(sh[:, 0, :] > 0)  # the lit box: positive mean radiance everywhere inside
    assert "total" in result.stderr and "s" in result.stderr


def test_sample_writes_exactly_the_out_path_it_is_given(tmp_path, points):
    """`--out sh.txt` is sh.txt (numpy alone would write sh.txt.npy), and nothing else is left beside it."""
    out = tmp_path / "sh.txt"
    result = run("sample", "cornell", "--points", points, "--method", "solver", "--out", out,
                 "--voxels", "8", "--probes", "4", "--directions", "64")
    assert result.returncode == 0, result.stderr
    assert np.load(out).shape == (3, 9, 3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["points.npy", "sh.txt"]


def test_a_scene_without_emitters_gives_a_black_finite_field(tmp_path, points):
    scene = tmp_path / "dark.obj"
    scene.write_text("v -1 -1 -1\nv 1 -1 -1\nv 1 -1 1\nv -1 -1 1\nv 0 1 0\nf 1 3 2\nf 1 4 3\nf 1 2 5\n")
    out = tmp_path / "sh.npy"
    result = run("sample", scene, "--points", points, "--out", out, "--voxels", "8", "--probes", "4")
    assert result.returncode == 0, result.stderr
    sh = np.load(out)
    assert np.all(np.isfinite(sh)) and np.all(sh == 0)


def test_a_flat_scene_samples_with_only_the_timing_line_on_stderr(tmp_path, points):
    """A lamp alone has no depth: its probe box gets some (Scene.bounds), where a zero probe spacing used
    to divide by zero and print numpy's warning with a stray source line, then crash."""
    write(tmp_path / "lamp.mtl", "newmtl lamp\nKe 4 4 4\n")
    scene = write(tmp_path / "lamp.obj", "mtllib lamp.mtl\nusemtl lamp\n"
                  "v -1 1 -1\nv 1 1 -1\nv 1 1 1\nv -1 1 1\nf 1 2 3\nf 1 3 4\n")  # facing down
    out = tmp_path / "sh.npy"
    result = run("sample", scene, "--points", points, "--out", out, "--voxels", "8", "--probes", "4",
                 "--directions", "64")
    assert result.returncode == 0, result.stderr
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("sample solver:"), result.stderr
    sh = np.load(out)
    assert np.all(np.isfinite(sh)) and np.all(sh[:, 0, :] > 0)  # every point is below the lamp


def test_neural_sample_warns_on_a_scene_outside_the_models_training_domain(tmp_path, points):
    """The Cornell box with a near-white back wall (0.99; the shipped model trained up to 0.95): a warning
    line on stderr that names the albedo and the physical solver, the probes all the same, exit 0."""
    if not (ROOT / "models" / "probenet.onnx").is_file():
        pytest.skip("no shipped model")
    source = ROOT / "assets" / "scenes"
    obj = (source / "cornell.obj").read_text()
    write(tmp_path / "white.obj", obj.replace("mtllib cornell.mtl", "mtllib white.mtl"))
    materials = (source / "cornell.mtl").read_text().split("newmtl back\nKd 0.885809 0.698859 0.666422")
    write(tmp_path / "white.mtl", "newmtl back\nKd 0.99 0.99 0.99".join(materials))
    out = tmp_path / "sh.npy"
    result = run("sample", tmp_path / "white.obj", "--points", points, "--method", "neural", "--out", out)
    assert result.returncode == 0, result.stderr
    warning, timing = result.stderr.strip().splitlines()
    assert warning.startswith("warning: ") and "'back' albedo 0.99 is above the trained 0.95" in warning
    assert "physical solver" in warning and timing.startswith("sample neural:")
    assert np.load(out).shape == (3, 9, 3)
    inside = run("sample", "cornell", "--points", points, "--method", "neural", "--out", out)
    assert inside.returncode == 0 and "warning" not in inside.stderr, inside.stderr


def write(path: Path, content) -> Path:
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return path


BAD_SCENES = {
    "missing": lambda d: d / "nope.obj",
    "directory": lambda d: d,
    "unsupported": lambda d: write(d / "scene.fbx", "whatever"),
    "empty obj": lambda d: write(d / "empty.obj", ""),
    "no faces": lambda d: write(d / "points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"),
    "index out of range": lambda d: write(d / "bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n"),
    "nan vertex": lambda d: write(d / "nan.obj", "v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
    "binary garbage obj": lambda d: write(d / "garbage.obj", bytes(range(256)) * 4),
    "corrupt glb": lambda d: write(d / "bad.glb", b"glTF\x02\x00\x00\x00garbage"),
    "corrupt ply": lambda d: write(d / "bad.ply", "ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n"),
    "unknown built-in": lambda d: Path("no-such-builtin"),
}


@pytest.mark.parametrize("case", sorted(BAD_SCENES))
def test_bad_scenes_exit_2_with_one_line(tmp_path, points, case):
    scene = BAD_SCENES[case](tmp_path)
    result = run("sample", scene, "--points", points, "--out", tmp_path / "sh.npy", "--voxels", "8")
    assert result.returncode == 2, (case, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert not (tmp_path / "sh.npy").exists()


BAD_POINTS = {
    "missing": None,
    "wrong shape": np.zeros((4, 2), np.float32),
    "empty": np.zeros((0, 3), np.float32),
    "nan": np.array([[0, np.nan, 0]], np.float32),
    "strings": np.array([["a", "b", "c"]]),
    "not npy": b"this is not an npy file",
    "pickled objects": np.array([[object(), 1, 2]], dtype=object),
    "an npz archive": "npz",
}


@pytest.mark.parametrize("case", sorted(BAD_POINTS))
def test_bad_points_exit_2_with_one_line(tmp_path, case):
    path = tmp_path / "p.npy"
    value = BAD_POINTS[case]
    if isinstance(value, bytes):
        path.write_bytes(value)
    elif isinstance(value, str):   # an .npz archive renamed .npy
        with open(path, "wb") as fh:
            np.savez(fh, points=np.zeros((3, 3), np.float32))
    elif value is not None:
        np.save(path, value, allow_pickle=True)
    result = run("sample", "cornell", "--points", path, "--out", tmp_path / "sh.npy", "--voxels", "8")
    assert result.returncode == 2, (case, result.stderr)
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr


@pytest.mark.parametrize("args", [["--voxels", "0"], ["--probes", "-3"], ["--kernel", "magic"],
                                  ["--method", "psychic"], ["--voxels", "ten"], ["--sun", "1,2,3"],
                                  ["--sun", "0,0,0,1,1,1"], ["--dering", "3"]])
def test_bad_options_exit_2_with_one_line(tmp_path, points, args):
    result = run("sample", "cornell", "--points", points, "--out", tmp_path / "sh.npy", *args)
    assert result.returncode == 2, (args, result.stderr)
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr


def test_output_into_a_missing_folder_is_bad_input(tmp_path, points):
    result = run("sample", "cornell", "--points", points, "--out", tmp_path / "no" / "sh.npy")
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1


def test_capture_views_match_the_renderer():
    from viewer.cli import VIEWS
    from viewer.gpu.renderer import VIEWS as RENDERER_VIEWS

    assert VIEWS == RENDERER_VIEWS


@pytest.mark.parametrize("args", [["--size", "0x10"], ["--size", "big"], ["--camera", "1,2"], ["--fov", "500"],
                                  ["--view", "xray"], ["--exposure", "nan"], ["--exposure", "inf"],
                                  ["--camera=nan,0,3,0,0,0"], ["--camera=0,0,1,0,0,1"], ["--camera=1e30,0,0,0,0,0"],
                                  ["--msaa", "3"], ["--msaa=-1"], ["--msaa", "many"], ["--lightmap-faces=-1"]])
def test_bad_capture_options_exit_2_with_one_line(tmp_path, args):
    result = run("capture", "cornell", "--out", tmp_path / "x.png", "--gi", "off", *args)
    assert result.returncode == 2, (args, result.stderr)
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr


def test_capture_writes_a_png(tmp_path):
    out = tmp_path / "box.png"
    result = run("capture", "cornell", "--out", out, "--size", "64x48", "--gi", "off", "--msaa", "0")
    assert result.returncode == 0, result.stderr
    from PIL import Image

    assert Image.open(out).size == (64, 48)


def test_neural_without_a_model_is_refused_in_one_line(tmp_path, points):
    result = run("sample", "cornell", "--points", points, "--method", "neural", "--model",
                 tmp_path / "missing.onnx", "--out", tmp_path / "sh.npy")
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert "model" in result.stderr


def test_capture_with_compute_gi_is_brighter_in_shadow_than_gi_off(tmp_path):
    from PIL import Image

    images = {}
    for gi in ("off", "compute"):
        out = tmp_path / f"{gi}.png"
        result = run("capture", "cornell", "--out", out, "--size", "64x64", "--gi", gi, "--msaa", "0",
                     "--voxels", "12", "--probes", "8", "--directions", "128")
        assert result.returncode == 0, result.stderr
        images[gi] = np.asarray(Image.open(out), np.float64)
    # the ceiling gets no direct light: only GI lights it
    ceiling = (slice(2, 8), slice(20, 44))
    assert images["compute"][ceiling].mean() > images["off"][ceiling].mean() + 10


# ---- the command line is the top floor --------------------------------------------------------------------

def imported_modules(source: str, package: str) -> set[str]:
    """The modules a file's source imports anywhere, inside functions too: `from viewer import cli` counts
    as viewer.cli, relative imports are resolved against package, import_module("...") is an import."""
    import ast

    found = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            found |= {base} | {f"{base}.{alias.name}" for alias in node.names}
        elif (isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", None))
              in ("import_module", "__import__") and node.args and isinstance(node.args[0], ast.Constant)):
            found.add(str(node.args[0].value))
    return found


def viewer_imports() -> dict[str, set[str]]:
    """Every module of viewer/ -> the modules it imports."""
    modules = {}
    for path in sorted((ROOT / "viewer").rglob("*.py")):
        name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        modules[name.removesuffix(".__init__")] = imported_modules(path.read_text(), package)
    return modules


def test_the_import_walk_sees_imports_inside_functions():
    source = "def run():\n    from viewer import cli\n    from .cli import InputError\n"
    assert {"viewer.cli", "viewer.cli.InputError"} <= imported_modules(source, "viewer")
    assert "viewer.cli" in imported_modules("importlib.import_module('viewer.cli')", "viewer")


def test_nothing_below_the_command_line_imports_it():
    """viewer/cli.py imports the commands (the viewer, the benchmark, the capture); none of them imports it
    back: what they share with it (InputError, run_capture) lives below, in viewer.errors and viewer.capture."""
    modules = viewer_imports()
    importers = {name for name, imports in modules.items()
                 if any(m == "viewer.cli" or m.startswith("viewer.cli.") for m in imports)}
    assert importers == {"viewer.__main__"}
    assert {"viewer.ui.options", "viewer.bench.run", "viewer.capture", "viewer.errors"} <= modules["viewer.cli"]


def test_the_viewer_and_the_benchmark_do_not_import_each_others_command_line():
    modules = viewer_imports()
    viewer_side, bench_side = ("viewer.app", "viewer.ui.options"), ("viewer.bench.run",)
    for module, other_side in [*((m, bench_side) for m in viewer_side), *((m, viewer_side) for m in bench_side)]:
        crossing = {m for m in modules[module] if m.startswith(other_side)}
        assert not crossing, f"{module} imports {crossing}"


def test_an_error_naming_a_file_is_one_printable_line(tmp_path):
    """A file name holding a newline and a terminal escape cannot print a forged `error:` line."""
    name = tmp_path / "room\nerror: forged\x1b[31m.obj"
    result = run("capture", name, "--out", tmp_path / "x.png")
    assert result.returncode == 2
    assert len(result.stderr.splitlines()) == 1 and "\x1b" not in result.stderr, result.stderr
