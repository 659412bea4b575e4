"""The direct light on the voxels (viewer/neural/irradiance.py): the light the seen and bounce features
start from."""

import numpy as np
import pytest

from scenes import box, ceiling_lamp, lit_room
from viewer.neural import encoding
from viewer.scene import Scene


def voxel_direct(scene: Scene, m: int):
    """(voxels, their direct irradiance) on the encoding's lattice of m^3 cells over the scene."""
    grid, _, received = encoding.lit_voxels(scene, m)
    return grid, received


def test_under_a_lamp_the_irradiance_is_its_integral_and_surfaces_turned_away_get_none():
    """A block's top 1.95 below a lamp 0.4 wide: the voxel under the lamp receives L x the integral of
    cos cos / r^2 over the lamp; the block's sides, turned away from it, and its underside get nothing."""
    scene = Scene.concatenate("lamp-above-block", [ceiling_lamp(half_size=0.2, height=0.95, radiance=10.0),
                                                   box(half_size=1.0, centre=(0, -2.0, 0), name="block")])
    grid, received = voxel_direct(scene, 24)
    top = np.flatnonzero(grid.normal[:, 1] > 0.99)
    under = top[np.argmin(np.linalg.norm(grid.position[top][:, [0, 2]], axis=1))]
    point = encoding.surface_points(grid)[under]
    u = (np.arange(400) + 0.5) / 400 * 0.4 - 0.2
    x, z = np.meshgrid(u - point[0], u - point[2])
    h = 0.95 - point[1]
    expected = 10.0 * float(np.sum(h * h / (x * x + h * h + z * z) ** 2) * (0.4 / 400) ** 2)
    assert received[under] == pytest.approx(np.full(3, expected), rel=0.01)
    turned_away = np.flatnonzero(grid.normal[:, 1] < 0.5)
    assert len(turned_away) > 0 and np.all(received[turned_away] == 0.0)


@pytest.mark.parametrize("make", ["lit room", "sunlit room"])
def test_the_voxels_direct_light_is_the_solvers(make):
    """On the same voxels, the voxels' direct light is the physical solver's (its lamp paths and sun
    rays): in total within 1%, voxel by voxel within 3% of the total (area-weighted; measured 0.4% and
    0.6-2.5% on the Cornell box, paper-test and two validation rooms). The outer faces of a sunlit
    room's walls start their rays inside the wall, as the solver's do, and do not see the sun."""
    from viewer.physical.gi import GISettings, PhysicalGI
    from viewer.training import dataset

    if make == "lit room":
        scene = lit_room(box(half_size=0.25, centre=(0.3, -0.75, 0.2), albedo=0.8, name="block"))
    else:
        scene = dataset.make_scene("val", 2, 14, "v2")[0]
        assert scene.sun is not None and np.any(np.asarray(scene.sun.irradiance) > 0)
    grid, received = voxel_direct(scene, 24)
    solver = PhysicalGI(GISettings(voxels=24, probes=24))
    solver.update(scene)
    assert solver.geometry.voxels.count == grid.count
    truth = solver.lighting.direct.astype(np.float64)
    area = grid.area[:, None]
    total = float((area * truth).sum())
    assert float((area * received).sum()) == pytest.approx(total, rel=0.01)
    assert float((area * np.abs(received - truth)).sum()) < 0.03 * total
