"""The share of each voxel's surface the sun reaches (viewer/rays/sun.py): the sunlight the voxels catch
is the sunlight that enters, and none reaches a closed room."""

import numpy as np
import pytest

from viewer.bench.stability.sun import entering_power, sunny_room
from viewer.neural.encoding import occluders
from viewer.physical import geometry
from viewer.rays import sun
from viewer.rays.voxels import voxelize
from viewer.scene import DirectionalLight, Scene
from scenes import box, ceiling_lamp


def caught_share(scene, window: dict, voxels: int) -> float:
    """The sunlight the voxels catch (irradiance x cosine x area x the share the sun reaches) over what
    enters through the window."""
    grid = voxelize(scene, voxels)
    direction = np.asarray(scene.sun.direction, np.float64)
    cosine = grid.normal @ direction
    lit = np.flatnonzero(cosine > 0)
    cover = sun.voxel_sun_cover(occluders(scene, grid), grid, direction)[lit]
    caught = float((cosine[lit] * cover * grid.area[lit]).sum() * np.mean(scene.sun.irradiance))
    return caught / entering_power(scene, window)


@pytest.mark.parametrize("side, worst", [(sun.SUN_SIDE, 0.035), (1, None)])
def test_the_voxels_catch_the_sunlight_that_enters_a_window(monkeypatch, side, worst):
    """Four rooms of the training generator with the sun through a window, at 24^3 and 32^3 voxels: the
    voxels catch within 3.5% of what enters (3.1% at worst). One ray a voxel drew the sunlit patch in
    whole voxels and caught up to 9.5% too little or 8% too much."""
    monkeypatch.setattr(sun, "SUN_SIDE", side)
    errors = []
    for number in range(4):
        scene, params = sunny_room(number)
        errors += [abs(caught_share(scene, params["window"], voxels) - 1.0) for voxels in (24, 32)]
    if worst is None:
        assert max(errors) > 0.08
    else:
        assert max(errors) <= worst


def test_no_sunlight_reaches_inside_a_closed_room():
    """A closed room under a low sun: no voxel of its inside is reached, though the points across the
    floor's voxels beside the walls lie on the floor's plane beyond them (those start at the voxel)."""
    parts = [box(inward=True, name="room"), ceiling_lamp(), box(0.2, centre=(0.1, -0.8, 0.2))]
    scene = Scene.concatenate("closed", parts, sun=DirectionalLight([0.3, 1.0, 0.2], [5.0, 5.0, 5.0]))
    grid = voxelize(scene, 24)
    direction = np.asarray(scene.sun.direction, np.float64)
    assert not np.any(sun.voxel_sun_cover(occluders(scene, grid), grid, direction))


def test_the_solver_and_the_network_see_the_same_share():
    """The physical solver's sun term takes the same share of each voxel as the network's input does."""
    scene, _ = sunny_room(2)
    settings = geometry.GeometrySettings(voxels=24, probes=4)
    traced = geometry.build(scene, settings)
    grid = traced.voxels
    direction = np.asarray(scene.sun.direction, np.float64)
    cosine = grid.normal @ direction
    found = geometry.sun_paths(traced, scene.sun).voxel_cosine
    cover = sun.voxel_sun_cover(occluders(scene, grid), grid, direction)
    np.testing.assert_allclose(found, np.maximum(cosine, 0.0) * cover, atol=1e-6)
    assert not np.any(cover[cosine <= 0])
    assert 0 < np.mean((cover > 0) & (cover < 1)) < 0.1   # a few voxels on the patch's edge, partly lit
