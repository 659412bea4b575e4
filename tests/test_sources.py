"""The registry of GI sources (viewer.sources): a source registered from outside the package is found by
every command and by the panel with no other file touched; the names users typed before still work."""

import time

import numpy as np
import pytest

from viewer import sources
from viewer.physical.gi import Timings
from viewer.probes.grid import ProbeGrid

CONSTANT = np.arange(27, dtype=np.float32).reshape(9, 3) / 27.0 + 0.5
"""Every probe's SH of the toy source: bright enough to light the picture."""


def constant_probes(scene, settings, options):
    m = settings.probes
    lo, hi = scene.bounds
    coefficients = np.broadcast_to(CONSTANT, (m, m, m, 9, 3)).copy()
    timings = options.timings if options.timings is not None else Timings()
    timings.stages["toy"] = 0.0
    return ProbeGrid(lo, hi, coefficients, np.ones((m, m, m), bool)), timings


@pytest.fixture
def toy():
    source = sources.register(sources.Source("toy", "Toy (constant)", solve=constant_probes))
    yield source
    sources.unregister("toy")


def test_sample_finds_a_registered_source(toy, tmp_path):
    from viewer.cli import main

    points, out = tmp_path / "points.npy", tmp_path / "sh.npy"
    np.save(points, np.array([[0.0, 0.0, 0.0], [0.5, -0.5, 0.2], [-0.6, 0.6, -0.3]], np.float32))
    assert main(["sample", "cornell", "--points", str(points), "--method", "toy", "--out", str(out),
                 "--voxels", "8", "--probes", "4"]) == 0
    sh = np.load(out)
    assert sh.shape == (3, 9, 3)
    assert sh == pytest.approx(np.broadcast_to(CONSTANT, sh.shape), abs=1e-6)


def test_capture_finds_a_registered_source(toy, tmp_path, gl_context):
    from PIL import Image

    from viewer.cli import main

    images = {}
    for gi in ("off", "toy"):
        out = tmp_path / f"{gi}.png"
        assert main(["capture", "cornell", "--out", str(out), "--size", "64x48", "--gi", gi, "--msaa", "0",
                     "--voxels", "8", "--probes", "4"]) == 0
        images[gi] = np.asarray(Image.open(out), np.float64)
    assert images["toy"].shape == (48, 64, 3)
    assert images["toy"].mean() > images["off"].mean() + 5   # its constant light is on screen


def test_the_panel_and_the_viewer_offer_a_registered_source(toy):
    from viewer.physical.gi import GISettings
    from viewer.scene import load
    from viewer.ui.gi_sources import GIController
    from viewer.ui.options import add_arguments
    from viewer.ui.panels import source_choices

    assert ("toy", "Toy (constant)") in source_choices()
    import argparse

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    assert parser.parse_args(["--gi", "toy"]).gi == "toy"
    gi = GIController(ctx=None, source="toy", settings=GISettings(voxels=8, probes=4))
    try:
        assert gi.source == "toy"
        gi.set_scene(load("cornell"), version=1)
        deadline = time.monotonic() + 600.0
        while time.monotonic() < deadline:
            changed, grid = gi.update()
            if changed and grid is not None:
                break
            time.sleep(0.01)
        assert grid.coefficients == pytest.approx(np.broadcast_to(CONSTANT, (4, 4, 4, 9, 3)))
        assert "done" in gi.status()[0] and not gi.busy
    finally:
        gi.close()


def test_unregistered_sources_are_gone():
    assert "toy" not in sources.SOURCES and "toy" not in sources.chosen_by_name()


def test_the_old_names_still_find_the_cpu_solver():
    assert sources.canonical("numpy") == sources.canonical("physical") == "solver"
    assert sources.lookup("numpy") is sources.SOURCES["solver"]
    with pytest.raises(sources.UnknownSource):
        sources.lookup("psychic")
    assert sources.renamed("numpy") == "solver" and sources.renamed("numpy-edit") == "solver-edit"
    assert sources.renamed("numpy:*") == "solver:*" and sources.renamed("numpy-paper:N16 M24 conv") == "solver-paper:N16 M24 conv"
    assert sources.renamed("mitsuba-probes") == "mitsuba-probes" and sources.renamed("numpyish") == "numpyish"


def test_the_benchmark_takes_its_old_method_names(tmp_path):
    """`--only 'numpy:*'` picks the CPU solver's rows, and a CSV written when the method was `numpy` counts
    as measured for `solver` (the benchmark resumes from its CSV)."""
    from viewer.bench import method_table, run

    table = method_table.registry(quick=True)
    chosen = run.select(table, ["numpy:*"])
    assert chosen and all(m.family == "solver" for m in chosen.values())
    csv = tmp_path / "benchmark.csv"
    csv.write_text(",".join(run.COLUMNS) + "\ncornell,numpy,N8 M8 conv,1,10,10,3,0.1,1,0,1,0.5,2026-11-25 10:00:00\n")
    [row] = run.read_rows(csv)
    assert run.key(row) == ("cornell", "solver", "N8 M8 conv")
    assert ("cornell", "solver", "N8 M8 conv") in {run.key(r) for r in run.read_rows(csv)}


def test_the_stability_suite_and_the_gallery_take_their_old_names():
    from viewer.bench import gallery
    from viewer.bench.stability import __main__ as stability

    assert stability.method_names(["physical", "compute"]) == ["solver", "compute"]
    assert gallery.source_names(["physical", "neural"]) == ["compute", "neural"]


def test_the_window_solves_nothing_for_an_unlit_scene_until_an_edit_lights_it(toy):
    """A scene with no emitter and no sun: the window's GI source is not started (its probes would be
    black after the scene's full solve time), the panel says why, and no indirect light is shown; an
    emission given to a material starts the source."""
    from dataclasses import replace

    from viewer.physical.gi import GISettings
    from viewer.scene import load
    from viewer.ui.gi_sources import GIController

    lit = load("cornell")
    unlit = replace(lit, emission=np.zeros_like(lit.emission))
    assert not unlit.has_emitters
    gi = GIController(ctx=None, source="toy", settings=GISettings(voxels=8, probes=4))
    try:
        gi.set_scene(unlit, version=1, new_scene=True)
        assert gi.update() == (True, None) and not gi.busy
        assert "Nothing emits light" in gi.status()[0]
        gi.set_scene(lit, version=2)
        deadline = time.monotonic() + 600.0
        grid = None
        while grid is None and time.monotonic() < deadline:
            changed, grid = gi.update()
            time.sleep(0.01)
        assert grid is not None and grid.coefficients == pytest.approx(np.broadcast_to(CONSTANT, (4, 4, 4, 9, 3)))
        assert "Nothing emits light" not in gi.status()[0]
    finally:
        gi.close()
