"""The shipped model (models/probenet.onnx): it loads, runs on every built-in scene, and holds the
accuracy its card claims on the paper's held-out scene, measured the way the card was."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from viewer.neural import field as neural
from viewer import scene as scenes

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "models" / "probenet.onnx"


@pytest.fixture(scope="module")
def field():
    return neural.NeuralField(MODEL)


def test_card_describes_the_file(field):
    card = json.loads(MODEL.with_suffix(".json").read_text())
    assert card["sha256"] == neural.file_sha256(MODEL)
    assert card["probes"]["resolution"] == field.resolution
    assert card["metrics"]["onnx_relative_difference"] < 1e-5
    for key in ("training", "metrics", "inputs", "outputs", "parameters"):
        assert card[key]


@pytest.mark.parametrize("name", scenes.builtin_names())
def test_runs_on_every_builtin_scene(field, name):
    scene = scenes.load(name)
    grid = field.solve(scene)
    c = grid.coefficients
    assert np.all(np.isfinite(c))
    assert np.percentile(c[..., 0, :], 5) > -0.05 * np.abs(c[..., 0, :]).max()  # DC: incident light is >= 0
    reflected = field.solve(scene, include_emitted=False).coefficients
    assert np.all(np.isfinite(reflected))
    assert reflected[..., 0, :].mean() < c[..., 0, :].mean()  # the reflected light is part of all the light


def test_meets_its_card_on_the_paper_test_scene(field):
    """Relative RMSE against Mitsuba at the card's free-space points, no worse than the card says."""
    from viewer.reference import mitsuba as reference
    from viewer.bench.accuracy import relative_rmse
    from viewer.evaluation.points import free_space_points

    card = json.loads(MODEL.with_suffix(".json").read_text())
    claimed = card["metrics"]["relative_rmse_vs_mitsuba"]["paper-test"]
    scene = scenes.load("paper-test")
    points = free_space_points(scene, 500, margin=0.06, seed=1)
    truth = reference.probe_sh(scene, points, directions=4096)
    error = relative_rmse(field.solve(scene).interpolate(points), truth)
    assert error <= claimed * 1.02 + 1e-3
    assert error < 0.20  # the bound every scene is held to


def test_sample_method_neural(tmp_path):
    points = tmp_path / "p.npy"
    np.save(points, np.array([[0.0, 0.0, 0.0], [0.3, -0.5, 0.2]], np.float32))
    out = tmp_path / "sh.npy"
    result = subprocess.run([sys.executable, "-m", "viewer", "sample", "paper-test", "--points", str(points),
                             "--method", "neural", "--out", str(out)], capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    sh = np.load(out)
    assert sh.shape == (2, 9, 3) and sh.dtype == np.float32 and np.all(sh[:, 0] > 0)
