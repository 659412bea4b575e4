"""The two-stage physical GI (viewer.physical.geometry + viewer.physical.relight): the physics holds, and an edit's relight
gives what a full solve of the edited scene gives."""

import numpy as np
import pytest

from viewer.physical import geometry
from viewer.physical import gi
from viewer.physical import lightpaths
from viewer.physical import relight
from viewer import scene as scenes
from scenes import box, lit_room


def free_space_radiance(grid):
    """Mean radiance per probe from the SH DC term."""
    return grid.coefficients[..., 0, :] / (0.282095 * 4 * np.pi)


@pytest.mark.parametrize("albedo, tolerance", [(0.5, 0.02), (0.9, 0.02), (0.99, 0.10)])
def test_white_furnace(albedo, tolerance):
    """Closed room, every surface emitting 1 with one albedo: L = 1 / (1 - albedo) everywhere, and the
    probes see it from every direction (higher SH bands vanish)."""
    room = box(inward=True, albedo=albedo, emission=1.0)
    grid = gi.solve(room, gi.GISettings(voxels=12, probes=4, directions=256))
    exact = 1.0 / (1.0 - albedo)
    assert np.all(np.abs(free_space_radiance(grid) / exact - 1.0) < tolerance)
    assert np.abs(grid.coefficients[..., 1:, :]).max() < 0.02 * grid.coefficients[..., 0, :].max()


def test_every_gather_ray_is_counted_in_a_closed_room():
    g = geometry.build(box(inward=True), geometry.GeometrySettings(voxels=10, probes=4))
    rows = np.asarray(g.transport.sum(axis=1)).ravel()
    assert np.allclose(rows, 1.0, atol=1e-6)


def solver(scene, **settings):
    gi_ = gi.PhysicalGI(gi.GISettings(voxels=16, probes=8, **settings))
    stages = gi_.update(scene)
    return gi_, stages


def test_a_colour_edit_relights_only_and_equals_a_full_solve():
    base = scenes.load("cornell")
    edited = base.with_albedo(base.groups[0], (0.9, 0.2, 0.6))
    warm, _ = solver(base)
    stages = warm.update(edited)
    assert stages == ["relight"]
    full, _ = solver(edited)
    a, b = warm.probe_grid().coefficients, full.probe_grid().coefficients
    assert np.abs(a - b).max() <= 1e-5 * np.abs(b).max()


def test_edits_materials_are_those_of_the_edited_scene_to_the_bit():
    """A colour edit's materials keep what it did not change (the voxel albedo of the faces not
    recoloured, the emission of an albedo edit) and are those made afresh for the edited scene, bit
    for bit, through albedo edits, a lamp's colour and back."""
    base = lit_room()
    warm, _ = solver(base)
    edits = [base.with_albedo("room", (0.9, 0.2, 0.6)), base.with_emission("lamp", (12.0, 6.0, 2.0)),
             base.with_emission("lamp", (12.0, 6.0, 2.0)).with_albedo("room", (0.1, 0.5, 0.5)), base]
    for edited in edits:
        assert warm.update(edited) == ["relight"]
        fresh = relight.materials(edited, warm.geometry, warm.lights)
        for name in ("albedo", "emission", "lamp", "sun"):
            np.testing.assert_array_equal(getattr(warm.materials, name), getattr(fresh, name))


def test_a_lamp_colour_and_intensity_edit_relights_only():
    base = lit_room()
    warm, _ = solver(base)
    edited = base.with_emission("lamp", (12.0, 6.0, 2.0))
    assert warm.update(edited) == ["relight"]
    full, _ = solver(edited)
    assert np.abs(warm.probe_grid().coefficients - full.probe_grid().coefficients).max() \
        <= 1e-5 * np.abs(full.probe_grid().coefficients).max()


def test_a_lamp_move_rebuilds_the_lamp_paths_not_the_geometry_when_allowed():
    base = lit_room()
    moved = base.transformed_group("lamp", np.array([[1, 0, 0, 0.2], [0, 1, 0, -0.1], [0, 0, 1, 0], [0, 0, 0, 1.0]]))
    warm, _ = solver(base)
    assert warm.update(moved, stale_geometry=True) == ["lights", "relight"]
    assert warm.update(moved) == ["geometry", "lights", "sun", "relight"]


def test_warm_start_converges_to_the_cold_answer():
    scene = scenes.load("paper-test")
    g = geometry.build(scene, geometry.GeometrySettings(voxels=16, probes=8))
    lights = lightpaths.build(scene, g)
    sun = geometry.sun_paths(g, scene.sun)
    mat = relight.materials(scene, g, lights)
    cold = relight.solve(g, lights, sun, mat)
    # start from a wrong answer: twice the light, and from the light of another albedo
    wrong = relight.Lighting(2 * cold.reflected, cold.direct, 0)
    warm = relight.solve(g, lights, sun, mat, previous=wrong)
    assert np.abs(warm.reflected - cold.reflected).max() <= 1e-3 * np.abs(cold.reflected).max()
    again = relight.solve(g, lights, sun, mat, previous=cold)
    assert again.sweeps <= 2


def test_bounces_add_light_and_converge():
    scene = scenes.load("cornell")
    g = geometry.build(scene, geometry.GeometrySettings(voxels=16, probes=8))
    lights, sun = lightpaths.build(scene, g), geometry.sun_paths(g, scene.sun)
    mat = relight.materials(scene, g, lights)
    totals = [relight.solve(g, lights, sun, mat, relight.RelightSettings(bounces=b)).reflected.sum() for b in (1, 2, 4)]
    converged = relight.solve(g, lights, sun, mat).reflected.sum()
    assert totals == sorted(totals) and totals[-1] <= converged * (1 + 1e-5)
    assert totals[1] > 1.05 * totals[0]
    assert converged - totals[2] < 0.15 * converged          # most light is in the first bounces


def test_lamp_light_is_linear_in_its_radiance():
    """Direct light from the lamp paths scales with the lamp's radiance (what makes an intensity edit
    one small product)."""
    scene = lit_room()
    g = geometry.build(scene, geometry.GeometrySettings(voxels=12, probes=6))
    lights = lightpaths.build(scene, g)
    sun = geometry.sun_paths(g, None)
    one = relight.direct_irradiance(lights, sun, relight.materials(scene, g, lights))
    three = relight.direct_irradiance(lights, sun, relight.materials(scene.with_emission("lamp", 15.0), g, lights))
    assert np.allclose(three, 3 * one, rtol=1e-5)
    assert one.max() > 0


def test_invalid_probes_are_filled_as_fill_invalid_does():
    from viewer.probes.grid import fill_invalid

    scene = scenes.load("cornell")
    g = geometry.build(scene, geometry.GeometrySettings(voxels=16, probes=12))
    assert not g.valid.all()
    rng = np.random.default_rng(0)
    raw = rng.normal(size=(12 ** 3, 9, 3)).astype(np.float32)
    ours = relight.probe_grid(g, raw).coefficients
    assert np.allclose(ours, fill_invalid(raw.reshape(12, 12, 12, 9, 3), g.valid), atol=1e-5)


def test_lamp_columns_give_the_patch_by_patch_light():
    """Summing each lamp's patches (one column per lamp) gives the same light as patch by patch."""
    scene = scenes.load("cornell")
    g = geometry.build(scene, geometry.GeometrySettings(voxels=16, probes=8))
    lights = lightpaths.build(scene, g)
    mat = relight.materials(scene, g, lights)
    voxel_matrix, radiance = lights.columns(mat.lamp)
    probe_matrix, _ = lights.columns(mat.lamp, probes=True)
    assert probe_matrix.shape[1] < lights.count
    assert np.allclose(probe_matrix @ radiance, lights.probe_matrix() @ mat.lamp, rtol=1e-4, atol=1e-6)
    assert np.allclose(voxel_matrix @ radiance, lights.voxel_irradiance @ mat.lamp, rtol=1e-4, atol=1e-6)


def test_the_indirect_light_never_makes_the_lamps_probe_matrix():
    """The renderer shades the lamps itself: its probes (include_emitted=False) need no lamp SH at the
    probes, the costliest part of the lamp paths, so a lamp drag does not pay for it."""
    physical, _ = solver(lit_room())
    physical.probe_grid(include_emitted=False)
    assert "patch" not in physical.lights._probes
    physical.probe_grid(include_emitted=True)
    assert "patch" in physical.lights._probes
