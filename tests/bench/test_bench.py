"""`python -m viewer bench`: the quick mode (what CI runs) writes a CSV, charts and a report whose numbers
mean what they say; the Pareto front is the set of entries nothing beats in both time and error."""

import csv
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

from viewer.bench.pareto import Entry, budget_sentences, front

ROOT = Path(__file__).resolve().parents[2]


def bench(*args):
    return subprocess.run([sys.executable, "-m", "viewer", "bench", *map(str, args)], capture_output=True,
                          text=True, cwd=ROOT, timeout=600)


def test_quick_mode_writes_sane_numbers_charts_and_report_and_resumes(tmp_path):
    result = bench("--quick", "--out", tmp_path)
    assert result.returncode == 0, result.stderr
    with open(tmp_path / "data" / "benchmark.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    methods = {r["method"] for r in rows}
    assert {"ambient", "mitsuba", "solver"} <= methods
    for r in rows:
        ms, error = float(r["ms"]), float(r["relative_rmse"])
        assert math.isfinite(ms) and ms > 0, r
        assert math.isfinite(error) and 0.0 <= error <= 5.0, r
        assert int(r["memory_bytes"]) >= int(r["texture_bytes"]) > 0, r
    mitsuba = sorted((int(r["setting"][1:]), float(r["relative_rmse"])) for r in rows if r["method"] == "mitsuba")
    errors = [e for _, e in mitsuba]
    assert len(errors) >= 3 and errors == sorted(errors, reverse=True), mitsuba  # more directions, less noise
    assert errors[-1] < 0.08  # 256 directions: a few percent (the reference itself has 4096)
    solvers = [float(r["relative_rmse"]) for r in rows if r["method"] in ("solver", "compute")]
    assert all(e < 0.4 for e in solvers)  # coarse grids (8^3 probes), but far better than a constant
    ambient = float(next(r["relative_rmse"] for r in rows if r["method"] == "ambient"))
    assert ambient > max(solvers)
    for chart in ("benchmark_time.png", "benchmark_memory.png", "benchmark_scenes.png"):
        assert (tmp_path / "images" / chart).stat().st_size > 10_000
    report = (tmp_path / "BENCHMARK.md").read_text()
    assert "| method | setting |" in report and "relative RMSE" in report

    again = bench("--quick", "--out", tmp_path, "--only", "mitsuba:*")
    assert again.returncode == 0, again.stderr
    assert "0 to measure" in again.stderr
    with open(tmp_path / "data" / "benchmark.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == len(rows)

    redo = bench("--quick", "--out", tmp_path, "--only", "ambient:*", "--again")
    assert redo.returncode == 0, redo.stderr
    assert "1 rows to measure again" in redo.stderr and "1 to measure" in redo.stderr
    with open(tmp_path / "data" / "benchmark.csv", newline="") as fh:
        after = list(csv.DictReader(fh))
    assert len(after) == len(rows) and [r["method"] for r in after].count("ambient") == 1


def entry(family, ms, error, field=True):
    return Entry(family, "s", field, ms, error, 1024, {})


def test_front_keeps_what_nothing_beats_in_both_time_and_error():
    fast_rough, slow_fine = entry("a", 10, 0.5), entry("b", 1000, 0.04)
    beaten = entry("c", 2000, 0.05)          # slower and worse than b
    middle = entry("d", 100, 0.1)
    points_only = entry("mitsuba", 5, 0.01, field=False)  # no field: drawn, never on the front
    assert front([beaten, slow_fine, points_only, middle, fast_rough]) == [fast_rough, middle, slow_fine]
    text = " ".join(budget_sentences([beaten, slow_fine, middle, fast_rough]))
    assert "10 ms to 100 ms: **a s**" in text and "1.0 s and more: **b s**" in text


def test_a_folder_without_scene_files_is_bad_input(tmp_path):
    result = bench(tmp_path, "--out", tmp_path)
    assert result.returncode == 2
    assert "no scene files" in result.stderr and "Traceback" not in result.stderr


def test_the_stability_suite_is_not_run_into_a_quick_or_elsewhere_report(tmp_path):
    result = bench("--quick", "--stability", "--out", tmp_path)
    assert result.returncode == 2 and "--stability" in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "data").exists()


def test_every_sweep_model_is_a_neural_entry_with_its_file_in_its_memory(tmp_path):
    """A model exported as the sweep writes it (runs/sweep/<run>/<name>.onnx + card) becomes an entry
    whose memory is its 8^3 textures plus the .onnx file, and whose producer gives the probe grid."""
    import json

    import pytest

    pytest.importorskip("torch", reason="the train extra (torch) builds the model")
    from viewer.bench.methods import model_files, neural_method, texture_bytes
    from viewer.scene import load
    from viewer.training import export
    from viewer.training.models import ProbeNet, ProbeNetConfig

    assert model_files(tmp_path) == []  # nothing shipped, no sweep: no entries, no error
    path = tmp_path / "runs" / "sweep" / "tiny-e1" / "tiny.onnx"
    path.parent.mkdir(parents=True)
    model = ProbeNet(ProbeNetConfig(width=4, hidden=8, levels=2)).eval()
    export.export_onnx(model, path, 8)
    export.write_card(path, model, 8, training={"note": "untrained, for tests"}, metrics={})
    card = json.loads(path.with_suffix(".json").read_text())
    card["inputs"]["voxels"] = 16
    path.with_suffix(".json").write_text(json.dumps(card))

    assert model_files(tmp_path) == [path]
    method = neural_method(path, root=tmp_path)
    assert method.name == "neural:runs/sweep/tiny-e1/tiny.onnx"
    assert method.memory_bytes == texture_bytes(8) + path.stat().st_size
    grid = method.prepare()(load("cornell"), None)
    assert grid.resolution == 8
    # the sweep's model shipped: one row, the shipped one's
    shipped = tmp_path / "models" / "probenet.onnx"
    shipped.parent.mkdir()
    shipped.write_bytes(path.read_bytes())
    assert model_files(tmp_path) == [shipped]


def test_a_screen_edit_is_timed_to_the_settled_frame_and_scored_by_the_sources_field():
    """`screen-edit`: the untimed half edits the scene away in the viewer, the timed half brings it back
    and returns once the viewer has settled (probes in, the lightmap's weights made and its gather done);
    the grid scored is the source's field of the scene itself."""
    from viewer.bench.edit_methods import screen_edit_method
    from viewer.physical.gi import GISettings, solve
    from viewer.scene import load

    scene = load("cornell")
    produce = screen_edit_method("compute", "colour").prepare()
    try:
        produce.before(scene)
        viewer = produce.viewer
        assert not np.array_equal(viewer.session.scene.albedo, scene.albedo) and viewer.settled
        grid = produce(scene, None)
        assert viewer.settled and not viewer.renderer.baking
        np.testing.assert_array_equal(viewer.session.scene.albedo, scene.albedo)
        np.testing.assert_allclose(grid.coefficients, solve(scene, GISettings()).coefficients, rtol=1e-6)
    finally:
        produce.release()
