"""The compute-shader solver (EGL; Mesa llvmpipe in CI) against the numpy solver and the physics.

The GPU solver uses the numpy solver's quadrature throughout (light samples, surface offsets, row
clamps, marching, Fibonacci directions), so the two must agree far inside the 2% that the float32 GPU
arithmetic alone would allow. Sizes are small (16^3 voxels, 8^3 probes) so that the numpy reference
runs in seconds on a CPU.
"""

from __future__ import annotations

import numpy as np
import pytest

from viewer.physical import gi
from viewer.physical import projection
from viewer.physical import transport
from viewer.physical.gi import GISettings
from viewer.gpu import compute_scene
from viewer.gpu.compute_relight import solve_probes
from viewer.gpu.compute_solver import ComputeSettings, ComputeSolver
from viewer.rays import sun
from viewer.rays.raymarch import Tracer
from viewer.scene import DirectionalLight, Scene, load
from viewer.rays.voxels import voxelize
from scenes import box, furnace, quads_to_triangles

CORNELL = GISettings(voxels=16, probes=8)


@pytest.fixture(scope="session")
def ctx(gl_context):
    return gl_context


def relative_rmse(value: np.ndarray, reference: np.ndarray) -> float:
    return float(np.sqrt(np.mean((value - reference) ** 2)) / np.sqrt(np.mean(reference ** 2)))


def numpy_solve(scene: Scene, settings: GISettings):
    """gi.solve's steps, keeping the voxels' light too: (voxels, Radiosity, probes with emitted light,
    indirect-only probes)."""
    voxels = voxelize(scene, settings.voxels, settings.normal_mode)
    tracer = Tracer.build(voxels)
    g = transport.transition_matrix(voxels, settings.kernel, tracer)
    light = transport.solve(voxels, scene.sun, transport.TransportSettings(settings.kernel, settings.bounces),
                            transition=g, tracer=tracer)
    grids = [projection.project(voxels, light, scene.sun, scene.bounds,
                            projection.ProbeSettings(resolution=settings.probes, directions=settings.directions,
                                                 include_emitted=emitted, dering=settings.dering), tracer)
             for emitted in (True, False)]
    return voxels, light, *grids


@pytest.fixture(scope="module", params=transport.KERNELS)
def cornell(request):
    scene = load("cornell")
    settings = GISettings(voxels=CORNELL.voxels, probes=CORNELL.probes, kernel=request.param)
    return scene, settings, numpy_solve(scene, settings)


def sunlit_box() -> Scene:
    """A box on a floor in the sun, no emitters: sun shadows, and probes inside the box (invalid)."""
    floor = np.array([[-1.0, 0.0, -1.0], [-1.0, 0.0, 1.0], [1.0, 0.0, 1.0], [1.0, 0.0, -1.0]])
    cube = box(half_size=0.3, centre=(0.0, 0.3, 0.0), albedo=0.6)
    quad = quads_to_triangles(np.array([[0, 1, 2, 3]]))  # counter-clockwise seen from above
    ground = Scene("floor", floor, quad, np.full((2, 3), 0.5), np.zeros((2, 3)), np.zeros(2, np.int64), ("floor",))
    sun = DirectionalLight(np.array([0.4, 1.0, 0.3]), np.array([3.0, 2.5, 2.0]))
    return Scene.concatenate("sunlit-box", [ground, cube], sun=sun)


def test_cornell_probes_match_the_numpy_solver(ctx, cornell):
    scene, settings, (voxels, light, reference, _) = cornell
    solver = ComputeSolver(ctx, voxels, scene.sun, settings, scene.bounds).run()
    grid = solver.probe_grid(include_emitted=True)
    assert np.array_equal(grid.valid, reference.valid)
    assert relative_rmse(grid.coefficients, reference.coefficients) < 0.02
    solver.release()


def test_cornell_voxel_radiance_matches_the_numpy_solver(ctx, cornell):
    scene, settings, (voxels, light, _, indirect) = cornell
    solver = ComputeSolver(ctx, voxels, scene.sun, settings, scene.bounds).run()
    assert solver.bounces == light.bounces
    assert relative_rmse(solver.radiance(), light.radiance) < 0.01
    # every voxel, not only on average: within 1% of its brightest channel (or of a dim floor)
    floor = 1e-3 * light.radiance.max()
    error = np.abs(solver.radiance() - light.radiance).max(axis=1) / np.maximum(light.radiance.max(axis=1), floor)
    assert error.max() < 0.01
    # the renderer's indirect-only grid
    assert relative_rmse(solver.probe_grid(include_emitted=False).coefficients, indirect.coefficients) < 0.02
    solver.release()


@pytest.mark.parametrize("kernel", transport.KERNELS)
def test_sun_shadows_and_invalid_probes_match_the_numpy_solver(ctx, kernel):
    scene = sunlit_box()
    settings = GISettings(voxels=12, probes=6, kernel=kernel, directions=256)
    # the physical kernel runs through the two-stage solver on both sides (tests/gpu/test_compute_relight.py)
    reference = gi.solve(scene, settings) if kernel == "physical" else numpy_solve(scene, settings)[2]
    assert not reference.valid.all()  # probes inside the box
    grid = solve_probes(ctx, scene, settings, include_emitted=True)
    assert np.array_equal(grid.valid, reference.valid)
    assert relative_rmse(grid.coefficients, reference.coefficients) < 0.02


def test_sunlit_voxels_match_the_numpy_solver(ctx):
    """Each voxel's light in the sun, the share of its surface the sun reaches included (viewer/rays/sun.py,
    ported to the shader): within 1% of the numpy solver's, on a grid where the box's shadow edge leaves
    voxels partly lit."""
    scene = sunlit_box()
    settings = GISettings(voxels=16, probes=6, directions=256)
    voxels, light, _, _ = numpy_solve(scene, settings)
    cover = sun.voxel_sun_cover(Tracer.build(voxels), voxels, scene.sun.direction)
    assert np.any((cover > 0) & (cover < 1))
    solver = ComputeSolver(ctx, voxels, scene.sun, settings, scene.bounds).run()
    floor = 1e-3 * light.radiance.max()
    error = np.abs(solver.radiance() - light.radiance).max(axis=1) / np.maximum(light.radiance.max(axis=1), floor)
    assert error.max() < 0.01
    solver.release()


@pytest.mark.parametrize("kernel", transport.KERNELS)
def test_white_furnace_gives_radiance_two_everywhere(ctx, kernel):
    grid = solve_probes(ctx, furnace(), GISettings(voxels=10, probes=4, directions=256, kernel=kernel))
    radiance = grid.coefficients[..., 0, :] / (0.282095 * 4 * np.pi)
    assert np.all(np.abs(radiance / 2.0 - 1.0) < 0.02)
    assert np.abs(grid.coefficients[..., 1:, :]).max() < 0.02 * grid.coefficients[..., 0, :].max()


def test_stepping_with_a_small_budget_gives_the_blocking_result(ctx, monkeypatch):
    """Stepped in 5 ms slices, the solver updates the textures once per bounce and ends where the blocking
    run does. The steps run on a simulated clock that every reading moves on by 2 ms: on the real clock
    a loaded machine stretches one slice over several bounces and the count of updates depends on it."""
    from viewer.gpu import compute_solver

    scene = load("cornell")
    voxels = voxelize(scene, 12)
    settings = GISettings(voxels=12, probes=6)
    blocking = ComputeSolver(ctx, voxels, None, settings, scene.bounds).run()
    clock = [0.0]

    def reading() -> float:
        clock[0] += 2e-3
        return clock[0]

    monkeypatch.setattr(compute_solver.time, "perf_counter", reading)
    every_bounce = ComputeSettings(probe_update_share=1.0)
    solver = ComputeSolver(ctx, voxels, None, settings, scene.bounds, every_bounce)
    steps = updates = 0
    while not solver.converged:
        updates += solver.step(budget_ms=5.0)
        steps += 1
    assert steps > solver.bounces            # the work came in slices, not in one call
    assert updates == solver.bounces          # the textures changed with every bounce
    np.testing.assert_array_equal(solver.probe_grid().coefficients, blocking.probe_grid().coefficients)
    assert solver.step(5.0) is False          # nothing left to do
    blocking.release()
    solver.release()


def test_a_step_starts_no_slice_that_would_not_fit_its_budget(monkeypatch):
    """The scheduler of ComputeSolver.step on a simulated clock: a pass of 1000 items at 0.1 ms each,
    in 8 ms steps. After the first slice (one unit: the cost is not known yet) every step ends within
    its budget, and the pass is done in about 100 ms / (SLICE_SHARE-ish x 8 ms) steps, not in one."""
    from viewer.gpu import compute_solver

    clock = [0.0]
    monkeypatch.setattr(compute_solver.time, "perf_counter", lambda: clock[0])
    done = []

    def run(first, end):
        clock[0] += 1e-4 * (end - first)
        done.extend(range(first, end))

    solver = ComputeSolver.__new__(ComputeSolver)
    solver.ctx = type("NoGL", (), {"finish": lambda self: None})()
    solver.seconds, solver._item_seconds, solver.version, solver.converged = {}, {}, 0, False
    solver._work = solver._sliced("pass", 1000, 4, run)
    steps = []
    while not solver.converged:
        start = clock[0]
        solver.step(budget_ms=8.0)
        steps.append(1e3 * (clock[0] - start))
    assert done == list(range(1000))
    assert max(steps[1:]) <= 8.0 + 1e-9, steps
    assert 12 <= len(steps) <= 25, steps


def test_a_light_change_restarts_without_tracing_the_geometry_again(ctx):
    scene = load("cornell")
    settings = GISettings(voxels=12, probes=6)
    solver = ComputeSolver(ctx, voxels=voxelize(scene, 12), settings=settings, bounds=scene.bounds).run()
    dimmer = voxelize(scene.with_emission("light", [6.0, 5.0, 4.0]), 12)
    solver.restart(dimmer)
    solver.run()
    assert "visibility" not in solver.seconds and "probe rays" not in solver.seconds
    fresh = ComputeSolver(ctx, dimmer, None, settings, scene.bounds).run()
    np.testing.assert_allclose(solver.probe_grid().coefficients, fresh.probe_grid().coefficients, rtol=1e-5, atol=1e-7)
    solver.release()
    fresh.release()


def test_visibility_traced_on_the_fly_equals_the_bitset(ctx):
    scene = load("cornell")
    voxels = voxelize(scene, 12)
    results = []
    for mode in ("bitset", "on-the-fly"):
        solver = ComputeSolver(ctx, voxels, None, GISettings(voxels=12, probes=4, bounces=3), scene.bounds,
                               ComputeSettings(visibility=mode)).run()
        results.append(solver.radiance())
        solver.release()
    np.testing.assert_allclose(results[1], results[0], rtol=1e-5, atol=1e-7)


def test_textures_hold_the_indirect_grid_in_half_floats(ctx):
    scene = load("cornell")
    solver = ComputeSolver(ctx, voxelize(scene, 12), None, GISettings(voxels=12, probes=6), scene.bounds).run()
    expected = solver.probe_grid(include_emitted=False).texture_data()
    for texture, volume in zip(solver.textures.textures, expected):
        stored = np.frombuffer(texture.read(), np.float16).reshape(volume.shape).astype(np.float32)
        np.testing.assert_allclose(stored, volume, rtol=2e-3, atol=1e-4)
    solver.release()


def test_work_cut_into_many_chunks_gives_the_same_light(ctx, monkeypatch):
    """llvmpipe stops all loops of an invocation after 65535 iterations in all, so long loops run in
    chunks (emitters, senders, directions, bits of a visibility word). Tiny chunks must not change
    the answer."""
    scene = load("cornell")
    voxels = voxelize(scene, 12)
    settings = GISettings(voxels=12, probes=4, directions=128)
    whole = ComputeSolver(ctx, voxels, None, settings, scene.bounds).run()
    monkeypatch.setattr(compute_scene, "LOOP_BUDGET", 2000)
    cut = ComputeSolver(ctx, voxels, None, settings, scene.bounds)
    t = cut.transport
    assert len(t.direct_chunks()) > 1 and len(t.sender_ranges()) > 1 and len(t.bit_ranges()) > 1
    cut.run()
    np.testing.assert_allclose(cut.radiance(), whole.radiance(), rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(cut.probe_grid().coefficients, whole.probe_grid().coefficients, rtol=1e-5, atol=1e-6)
    whole.release()
    cut.release()
