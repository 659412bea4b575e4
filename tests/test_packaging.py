"""A wheel is a working program: built from the sources, installed into a clean virtual environment and
run from a folder outside the repository, `gi-viewer` finds its shaders, its model and its built-in
scenes (viewer/resources.py), as a user's `pip install .`, pipx or uv would leave it.

The clean environment gets no network and no second copy of the dependencies: a .pth file makes the
test interpreter's site-packages visible to it. A .pth file that names a folder adds that folder to
sys.path but runs none of the .pth files inside it, so the editable install of the repository (a
finder that a .pth file in there starts) stays invisible; `viewer` can only come from the wheel, and
the tests check that it does. The whole file takes about 10 s here.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import site
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from conftest import missing

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_INPUTS = ("pyproject.toml", "README.md", "LICENSE", "viewer", "shaders", "models", "assets")
"""What building the wheel reads; copied, so that the repository's own build/ folder is neither used
(it may hold stale copies of deleted files) nor written."""
MOST_BYTES = 2_000_000
"""The wheel carries code, shaders, one small network and the built-in scenes, no training data or
documentation images (about 0.5 MB at 0.1.0)."""


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    if importlib.util.find_spec("setuptools") is None:
        missing("building the wheel without a network needs setuptools in the test environment")
    work = tmp_path_factory.mktemp("packaging")
    source = work / "source"
    source.mkdir()
    for name in PACKAGE_INPUTS:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(ROOT / name, source / name)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
                    "--no-index", "-w", work / "dist", source], check=True, capture_output=True, timeout=300)
    (built,) = (work / "dist").glob("gi_viewer-*.whl")
    return built


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory) -> dict:
    """A clean venv with the wheel installed; `run` runs its `gi-viewer` in a folder outside the repo."""
    work = tmp_path_factory.mktemp("venv")
    venv = work / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", venv], check=True, timeout=120)
    python = venv / "bin" / "python"
    purelib = Path(subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                  check=True, capture_output=True, text=True).stdout.strip())
    dependencies = [*site.getsitepackages(), sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]
    (purelib / "gi_viewer_test_dependencies.pth").write_text("\n".join(dict.fromkeys(dependencies)) + "\n")
    subprocess.run([sys.executable, "-m", "pip", "--python", python, "install", "-q", "--no-deps", "--no-index",
                    wheel], check=True, capture_output=True, timeout=300)
    elsewhere = work / "elsewhere"
    elsewhere.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIEWER_DEBUG")}

    def run(*args):
        return subprocess.run([str(a) for a in args], cwd=elsewhere, env=env, capture_output=True, text=True,
                              timeout=300)

    return {"venv": venv, "python": python, "gi-viewer": venv / "bin" / "gi-viewer", "run": run,
            "elsewhere": elsewhere}


def test_the_wheel_carries_every_shader_model_and_builtin_scene_and_no_more(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    expected = {f"viewer/_data/shaders/{p.name}" for p in (ROOT / "shaders").glob("*.glsl")}
    expected |= {f"viewer/_data/models/{p.name}" for p in (ROOT / "models").iterdir()
                 if p.suffix in (".onnx", ".json")}
    expected |= {f"viewer/_data/scenes/{p.name}" for p in (ROOT / "assets" / "scenes").iterdir()}
    assert expected <= names, sorted(expected - names)
    assert "viewer/_data/models/probenet.onnx" in names and "viewer/_data/scenes/cornell.obj" in names
    assert not [n for n in names if n.startswith(("docs/", "tests/", "runs/", "data/")) or n.endswith(".png")]
    assert wheel.stat().st_size < MOST_BYTES


def test_the_wheel_carries_the_license(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    licenses = [n for n in names if n.endswith("/LICENSE") and ".dist-info/" in n]
    assert licenses, names
    text = zipfile.ZipFile(wheel).read(licenses[0]).decode()
    assert "MIT License" in text and "gi-viewer contributors" in text


def test_the_installed_program_calls_itself_gi_viewer_in_its_help(installed):
    result = installed["run"](installed["gi-viewer"], "capture", "--help")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("usage: gi-viewer capture") and "python -m viewer" not in result.stdout
    words = " ".join(result.stdout.split())
    assert "cornell" in words and "(default: compute)" in words, words


def test_the_installed_program_is_the_wheel_not_the_checkout(installed):
    out = installed["run"](installed["python"], "-c",
                           "import viewer, viewer.resources as r; print(viewer.__file__); print(r.SHADERS)")
    assert out.returncode == 0, out.stderr
    module, shaders = map(Path, out.stdout.split())
    assert module.is_relative_to(installed["venv"]) and shaders.is_relative_to(installed["venv"])
    assert not module.is_relative_to(ROOT)


def test_installed_gi_viewer_captures_the_builtin_cornell_box_with_the_shipped_network(installed, gl_context):
    result = installed["run"](installed["gi-viewer"], "capture", "cornell", "--gi", "neural",
                              "--out", "cornell.png", "--size", "96x72", "--msaa", "1")
    assert result.returncode == 0, result.stderr
    image = np.asarray(Image.open(installed["elsewhere"] / "cornell.png").convert("RGB"), np.float64)
    assert image.shape == (72, 96, 3)
    assert image.mean() > 20  # a lit box, not a black frame


def test_installed_gi_viewer_samples_with_the_shipped_network_and_the_compute_shaders(installed, gl_context):
    np.save(installed["elsewhere"] / "points.npy", np.array([[0, 0, 0], [0.4, -0.5, 0.2]], np.float32))
    for method, extra in (("neural", ()), ("compute", ("--voxels", "8", "--probes", "4"))):
        result = installed["run"](installed["gi-viewer"], "sample", "cornell", "--points", "points.npy",
                                  "--method", method, "--out", f"{method}.npy", *extra)
        assert result.returncode == 0, result.stderr
        assert result.stderr.count("\n") == 1, result.stderr  # the timing line and nothing else
        sh = np.load(installed["elsewhere"] / f"{method}.npy")
        assert sh.shape == (2, 9, 3) and np.all(np.isfinite(sh)) and np.all(sh[:, 0] > 0), method
