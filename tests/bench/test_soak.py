"""Hours of use without growth (issue 13): after a warm-up, solve after solve and scene after scene
leave the resident memory where it was (within 10 MB) and not one more live GL object; bad files
dropped onto the window leave nothing behind either. Memory is measured after glibc has handed its free
heap back (viewer/memory.py), so that what is left is what something holds; GL objects are counted
with moderngl's context_gc mode on, so one freed without release() is still counted
(viewer/gpu/gl_objects.py). The soak command (python -m viewer.bench.soak) runs the same longer."""

from __future__ import annotations

import pytest

from viewer.physical.gi import GISettings
from viewer.memory import Usage
from viewer.scene import ASSETS, load

WARMUP = 5
STEPS = 30
MEMORY_MB = 10.0
SMALL = GISettings(voxels=8, probes=4, directions=64)
"""Small solves: each costs a fraction of a second, and allocates what a big one does, only less."""
SCENES = (ASSETS / "cornell.obj", ASSETS / "paper-test.obj")


def assert_flat(before: Usage, after: Usage, what: str) -> None:
    assert after.gl == before.gl, f"{what} changed the live GL objects: {before} -> {after}"
    assert after.rss_mb - before.rss_mb < MEMORY_MB, f"{what} grew the resident memory: {before} -> {after}"


@pytest.fixture
def ctx():
    from viewer.gpu.context import create_context
    from viewer.gpu.gl_objects import watch

    context = create_context()
    watch(context)
    yield context
    context.release()


def test_a_gl_object_freed_without_release_is_still_counted(ctx):
    from viewer.gpu.gl_objects import live_objects

    kept, released = ctx.buffer(reserve=64), ctx.texture((4, 4), 4)
    released.release()
    ctx.buffer(reserve=64)          # freed by Python at once, never released: leaks in GL
    counts = live_objects(ctx)
    assert counts == {"Buffer": 1, "dropped Buffer": 1}, counts
    kept.release()


@pytest.mark.parametrize("module", ["compute_relight", "compute_solver"])
def test_blocking_compute_solves_keep_memory_and_gl_objects_flat(ctx, module):
    """The blocking compute solves (the command line's and the benchmarks': the relight in compute
    shaders, and the all-pairs solver of the paper's kernel): their programs are compiled once per
    context, not compiled again and dropped by every solve, and each solve releases its buffers."""
    import importlib

    solve_probes = importlib.import_module(f"viewer.gpu.{module}").solve_probes

    scenes = [load(path) for path in SCENES]
    for step in range(WARMUP + STEPS):
        if step == WARMUP:
            before = Usage.measure(ctx, trim=True)
        grid = solve_probes(ctx, scenes[step % 2], SMALL, include_emitted=False)
    assert_flat(before, Usage.measure(ctx, trim=True), f"{STEPS} solves")
    assert grid.coefficients[..., 0, :].max() > 0, "the last solve gave no light"


def test_scene_swaps_in_the_viewer_keep_memory_and_gl_objects_flat():
    """The viewer's own path: a file opened as a drop opens it, solved by the compute source and drawn,
    then the next one; renderer, GI source and session release what the scene before made."""
    from viewer.bench.headless import HeadlessViewer

    viewer = HeadlessViewer("compute", SMALL, size=(160, 90))
    try:
        if viewer.gi.source != "compute":
            pytest.skip(viewer.gi.unavailable["compute"])
        for step in range(WARMUP + STEPS):
            if step == WARMUP:
                before = viewer.usage(trim=True)
            viewer.load(SCENES[step % 2])
            assert viewer.session.name == SCENES[step % 2].stem and "converged" in viewer.gi.status()[0]
        assert_flat(before, viewer.usage(trim=True), f"{STEPS} scene swaps")
    finally:
        viewer.release()


def test_bad_drops_leave_the_good_scene_and_nothing_else(display, x11, tmp_path):  # noqa: F811
    """20 bad files dropped onto the window, then a good one: that scene is shown, with the GL objects
    of one good drop."""
    from viewer.bench.soak_window import bad_files, good_files, viewer_arguments
    from viewer.bench.x11 import Viewer

    good = good_files(tmp_path, [ASSETS / "cornell.obj", ASSETS / "paper-test.obj"])
    bad = bad_files(tmp_path)
    viewer = Viewer(display, viewer_arguments(good[0], SMALL, gi="off"), tmp_path)
    try:
        window = viewer.ready()

        def drop(path, outcome: str) -> Usage:
            start = len(viewer.lines)
            assert x11.drop(window, [path])["finished"]
            viewer.wait_for(outcome, start=start)
            return Usage.parse(viewer.wait_for(r"resources: (.*)$", start=start).group(1))

        one_good = drop(good[1], r"loaded .*paper-test\.obj as 'paper-test'")
        for step in range(20):
            drop(bad[step % len(bad)], r"cannot load .*; keeping paper-test")
        after = drop(good[1], r"loaded .*paper-test\.obj as 'paper-test'")
        assert after.gl == one_good.gl, f"20 bad drops left GL objects behind: {one_good} -> {after}"
        x11.key("Escape")
        assert viewer.wait_exit() == 0
    finally:
        viewer.kill()
    assert "loads 2, load errors 20" in viewer.log
