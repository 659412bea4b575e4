"""Stability: what must hold at the edges (issue 5). docs/STABILITY.md measures where each method fails
and by how much (`python -m viewer.bench.stability`); the bounds here come from those numbers."""

import numpy as np
import pytest

from viewer.physical import gi
from viewer.probes import sh
from viewer.physical import transport
from viewer.evaluation.points import free_space_points
from viewer.bench.stability import scenes
from viewer.bench.stability.leaking import wall_points
from viewer.bench.stability.precision import clipped_volumes, compare
from viewer.gpu.probe_textures import texel_volumes
from viewer.rays.voxels import voxelize


@pytest.mark.parametrize("albedo", [0.9, 0.99])
def test_furnace_at_high_albedo_stays_finite_below_the_exact_light_and_within_its_kernel_tolerance(albedo):
    """White furnace, L = 1 / (1 - albedo) exactly. The solver may not diverge or create light (every
    voxel at most the exact answer), and it must reach what its own kernel allows: a receiver whose row
    gathers a fraction r of the hemisphere (r < 1: the discretised form factors miss ~1.5% of it on
    average) converges to at least 1 / (1 - albedo * min r). That is the furnace's tolerance here:
    ~40% low at 0.99 (docs/STABILITY.md, energy), not a 2% one."""
    voxels = voxelize(scenes.furnace(albedo), 8)
    g = transport.transition_matrix(voxels, "physical")
    light = transport.solve(voxels, settings=transport.TransportSettings(bounces=200), transition=g)
    exact = 1.0 / (1.0 - albedo)
    gathered = np.asarray(g.sum(axis=1)).ravel() / np.pi
    assert np.all(np.isfinite(light.radiance))
    assert light.radiance.max() <= exact * (1 + 1e-4)
    assert light.radiance.min() >= 0.99 / (1.0 - albedo * gathered.min())


def test_a_lamp_of_radiance_a_million_survives_the_half_float_probe_textures():
    """The probe coefficients exceed 65504 (half-float overflow): the per-grid power-of-two scale keeps
    every texel finite, every lit probe lit and the irradiance within half-float rounding, where clipping
    each coefficient (the packing before) turned 19% of the probes negative."""
    scene = scenes.lit_room(radiance=1e6)
    grid = gi.solve(scene, gi.GISettings(voxels=8, probes=6, directions=64))
    assert np.abs(grid.coefficients).max() > 65504
    packed = compare(grid, texel_volumes(grid)[0])
    assert packed["nonfinite"] == 0 and packed["black"] == 0 and packed["negative"] == 0
    assert packed["error"] < 2e-3
    assert compare(grid, clipped_volumes(grid))["error"] > 0.1   # the failure the scale removes


def test_bright_probes_come_back_from_the_gl_textures_as_they_went_in(gl_context):
    """Through the driver's own float-to-half conversion: a probe seeing a sun of irradiance 3e5 under a
    sky of radiance 2e4 (coefficients up to ~1.6e5) reads back finite and within half-float rounding."""
    from viewer.gpu.probe_textures import ProbeTextures
    from viewer.probes.grid import ProbeGrid

    directions = np.random.default_rng(3).normal(size=(2, 2, 2, 3))
    coefficients = sh.project_delta(directions, np.array([3e5, 2e5, 1e5]))
    coefficients[..., 0, :] += 2e4 * 0.282095 * 4 * np.pi
    grid = ProbeGrid(np.zeros(3), np.ones(3), coefficients, np.array([True, False] * 4).reshape(2, 2, 2))
    textures = ProbeTextures(gl_context, grid)
    try:
        volumes = [np.frombuffer(t.read(), np.float16).reshape(2, 2, 2, 4) for t in textures.textures]
    finally:
        textures.release()
    packed = compare(grid, volumes)
    assert packed["nonfinite"] == 0 and packed["black"] == 0 and packed["error"] < 2e-3


def test_deringing_keeps_the_probes_of_a_small_bright_lamp_non_negative():
    """A 0.1 x 0.1 lamp of radiance 500: without deringing the L2 probes near it ring below zero (-12% of
    their mean irradiance here; Mitsuba's own probes ring as much); with the poussin window at strength 1
    no probe has negative irradiance for any normal."""
    grid = gi.solve(scenes.lit_room(half_size=0.05, radiance=500.0), gi.GISettings(voxels=8, probes=8, directions=64))
    probes = grid.coefficients.reshape(-1, 9, 3)
    mean = np.pi * 0.282095 * probes[:, 0].mean(axis=-1)
    ringing = sh.min_irradiance_over_sphere(probes).min(axis=-1) / mean
    deringed = sh.min_irradiance_over_sphere(sh.dering(probes, 1.0)).min(axis=-1) / mean
    assert ringing.min() < -0.05                     # the scene does ring
    assert deringed.min() >= -1e-6


def test_light_leaking_through_a_wall_thinner_than_a_voxel_stays_small():
    """Two closed rooms divided by a wall 0.02 thick (1/18 of a voxel here): the dark room's true light is
    0. Measured at 12^3 voxels and probes: 0.66% of the lit room's light in free space (the trilinear
    probes across the wall; Mitsuba's own probes interpolated leak 0.28% at 16^3), 0.15% on the wall's dark
    face as the renderer shades it (23% without its leak reduction). Bounds: about twice that."""
    scene = scenes.two_rooms()
    grid = gi.solve(scene, gi.GISettings(voxels=12, probes=12, directions=128))
    points = free_space_points(scene, 400, margin=0.06, seed=5)
    dark = scenes.in_dark_room(points)
    light = grid.interpolate(points)[:, 0].mean(axis=-1)
    assert light[dark].mean() < 0.012 * light[~dark].mean()
    wall, normal = wall_points(False, +1)
    lit_wall, lit_normal = wall_points(False, -1)
    on_wall = np.maximum(grid.surface_irradiance(wall, normal), 0).mean()
    assert on_wall < 0.004 * np.maximum(grid.surface_irradiance(lit_wall, lit_normal), 0).mean()



def test_distance_from_the_training_set_is_zero_inside_the_ranges_and_grows_outside():
    """The out-of-distribution study's x axis (docs/STABILITY.md, out of distribution). Per axis: a room
    drawn with the first dataset's ranges lies inside the shipped model's (0), a room 2.0 x 0.8 x 0.8
    lies (2.0 - top) / width range widths outside on the room axis and nowhere else ((2.0 - 1.3) / 0.55
    = 1.3 for the first dataset's 0.75-1.3). Through the network input: a reference room's own encoding
    is at distance 0, and the elongated room lies farther from six reference rooms than a seventh room
    drawn like them."""
    from viewer.bench.stability.distance import VIEWS, EncodingDistance, scene_encoding
    from viewer.bench.stability.ood import TRAINED, range_distance
    from viewer.evaluation.procedural import Ranges, random_scene

    rooms = [random_scene(np.random.default_rng([7, k]), f"room-{k}") for k in range(7)]
    long_room, long_params = random_scene(np.random.default_rng(8), "long",
                                          Ranges(room_scale=((2.0, 0.8, 0.8), (2.0, 0.8, 0.8))))
    assert all(range_distance(axis, params) == 0.0 for _, params in rooms
               for axis in ("room", "colour", "light", "shape"))
    low, high = TRAINED.room_scale
    assert range_distance("room", long_params) == pytest.approx((2.0 - high) / (high - low))
    assert range_distance("colour", long_params) == 0.0 and range_distance("light", long_params) == 0.0
    inputs = [scene_encoding(scene, 8, 8) for scene, _ in rooms]
    long_inputs = scene_encoding(long_room, 8, 8)
    for view in VIEWS.values():
        measure = EncodingDistance(inputs[:6], view)
        assert measure(inputs[0]) == pytest.approx(0.0, abs=1e-9)
        assert measure(long_inputs) > measure(inputs[6])


def test_the_ood_study_moves_past_the_shipped_models_own_ranges():
    """The study reads what the network was trained on from its card (viewer.neural.domain) and steps past those
    ranges on each axis, whichever preset they are: every room of a step lies outside on its axis."""
    from viewer.bench.stability import ood
    from viewer.neural.field import DEFAULT_MODEL, ModelCard, ModelError
    from viewer.evaluation.procedural import PRESETS, random_scene

    try:
        assert ood.DOMAIN == ModelCard.read(DEFAULT_MODEL).domain
    except ModelError:
        assert ood.DOMAIN.ranges == "v1"
    assert ood.TRAINED == PRESETS[ood.DOMAIN.ranges]
    for preset, ranges in PRESETS.items():
        for number, step in enumerate(ood.steps(ranges)):
            if step.new or step.label == "on the walls only":   # new shapes and placements have no range
                continue
            _, params = random_scene(np.random.default_rng([ood.SEED, number]), "step", step.ranges)
            assert ood.range_distance(step.axis, params, ranges) > 0, (preset, step.label)


def test_the_input_study_rooms_are_what_their_cases_say():
    """Each case of the network's input study draws the rooms it names: two thin partitions, a small window
    with the sun, lights on objects alone, and every surface near black or near white."""
    from viewer.bench.stability import inputs

    rooms = {case.name: inputs.case_scenes(case, 1, n)[0] for n, case in enumerate(inputs.CASES)}
    thin = rooms["thin walls"]
    assert sum(name.startswith("partition") for name in thin.groups) == 2
    assert {"jamb", "wall"} <= set(rooms["thin wall, doorway"].groups)
    window = rooms["small window"]
    assert window.sun is not None
    glowing = rooms["glowing objects"]
    lit_groups = {glowing.groups[g] for g in np.unique(glowing.face_group[np.any(glowing.emission > 0, axis=1)])}
    assert lit_groups and not any(name.startswith("light") or name in ("floor", "ceiling", "back", "left-wall",
                                                                          "right-wall") for name in lit_groups)
    for case, (low, high) in (("near-black walls", inputs.DARK), ("near-white walls", inputs.WHITE)):
        room = rooms[case]
        surfaces = ~np.any(room.emission > 0, axis=1)      # the lamps' own faces keep their albedo
        assert room.albedo[surfaces].min() >= low and room.albedo[surfaces].max() <= high
