"""Light transport: the physics must hold (furnace, energy, convergence), for both kernels."""

import numpy as np
import pytest

from viewer.physical import gi
from viewer.physical import transport
from viewer import scene as scenes
from viewer.rays.raymarch import Tracer
from viewer.rays.voxels import voxelize
from scenes import box, furnace


def free_space_radiance(grid):
    """Mean radiance per probe from the SH DC term."""
    return grid.coefficients[..., 0, :] / (0.282095 * 4 * np.pi)


def test_white_furnace_gives_radiance_two_everywhere():
    grid = gi.solve(furnace(), gi.GISettings(voxels=10, probes=4, directions=256))
    radiance = free_space_radiance(grid)
    assert np.all(np.abs(radiance / 2.0 - 1.0) < 0.02)
    # isotropic: the higher SH bands vanish
    assert np.abs(grid.coefficients[..., 1:, :]).max() < 0.02 * grid.coefficients[..., 0, :].max()


@pytest.mark.parametrize("kernel", ["physical", "paper"])
def test_albedo_near_one_converges_without_creating_energy(kernel):
    """Closed room, emission 1, albedo 0.99. The bounce sum (with its geometric tail) must equal the
    exact solution of B = Le + T B, and no voxel may exceed the continuous answer 1 / (1 - 0.99) = 100:
    the rows of T gather at most the hemisphere. (The discrete rows gather ~2% less than pi, which at
    albedo 0.99 lowers B a lot: that is the furnace's sensitivity, not divergence.)"""
    room = box(inward=True, albedo=0.99, emission=1.0)
    voxels = voxelize(room, 8)
    g = transport.transition_matrix(voxels, kernel)
    light = transport.solve(voxels, settings=transport.TransportSettings(kernel=kernel, bounces=200), transition=g)
    t = (voxels.albedo[:, 0] / np.pi)[:, None] * g.toarray()
    # the solver's first bounce comes from the fine light samples, the rest through T
    first = voxels.albedo[:, 0] / np.pi * transport.direct_irradiance(voxels, kernel=kernel)[:, 0]
    exact = voxels.emission[:, 0] + np.linalg.solve(np.eye(voxels.count) - t, first)
    assert np.all(np.isfinite(light.radiance))
    assert np.allclose(light.radiance[:, 0], exact, rtol=0.01)
    assert exact.max() <= 100.0 * (1 + 1e-5)  # float32 rows


def test_bounces_add_light_monotonically_and_converge():
    voxels = voxelize(scenes.load("cornell"), 12)
    tracer = Tracer.build(voxels)
    g = transport.transition_matrix(voxels, "physical", tracer)
    totals = []
    for bounces in (1, 2, 4, 100):
        light = transport.solve(voxels, settings=transport.TransportSettings(bounces=bounces, extrapolate=False),
                                transition=g, tracer=tracer)
        totals.append(light.reflected.sum())
    assert totals == sorted(totals)
    assert (totals[3] - totals[2]) < 0.1 * totals[3]          # most light is in the first bounces
    assert totals[1] > 1.05 * totals[0]                         # ... but the second bounce counts


def test_transition_rows_never_gather_more_than_the_hemisphere():
    voxels = voxelize(scenes.load("paper-test"), 12)
    for kernel in transport.KERNELS:
        g = transport.transition_matrix(voxels, kernel)
        assert np.asarray(g.sum(axis=1)).max() <= np.pi * (1 + 1e-5)
        assert g.min() >= 0


def test_physical_kernel_is_reciprocal():
    """A_i G_ij = A_j G_ji, the form factor reciprocity, exact between voxels of equal area (the
    near-field clamp uses the sender's area, so it bends reciprocity slightly otherwise)."""
    voxels = voxelize(scenes.load("cornell"), 10)
    g = transport.transition_matrix(voxels, "physical").toarray()
    rows = np.asarray(g.sum(1)).ravel()
    unclamped = rows < np.pi * 0.999
    a = voxels.area
    sub = np.ix_(unclamped, unclamped)
    lhs = (a[:, None] * g)[sub]
    same_area = np.isclose(a[:, None], a[None, :], rtol=1e-6)[sub]
    assert same_area.sum() > 1000
    assert np.allclose(lhs[same_area], lhs.T[same_area], rtol=1e-4, atol=1e-9)


def test_a_scene_without_emitters_is_black_and_finite():
    room = box(inward=True, albedo=0.8, emission=0.0)
    grid = gi.solve(room, gi.GISettings(voxels=8, probes=4, directions=64))
    assert np.all(np.isfinite(grid.coefficients)) and np.all(grid.coefficients == 0)


def test_sun_lights_a_floor_with_cosine_falloff():
    floor = scenes.Scene("floor", np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], float),
                         np.array([[0, 2, 1], [0, 3, 2]]), 0.5, 0.0, 0, ("floor",))
    sun = scenes.DirectionalLight([0.0, 1.0, 1.0], [2.0, 2.0, 2.0])
    voxels = voxelize(floor, 8)
    light = transport.solve(voxels, sun)
    expected = 2.0 * np.cos(np.pi / 4)
    assert np.allclose(light.irradiance[:, 0], expected, rtol=1e-6)
    assert np.allclose(light.radiance[:, 0], 0.5 / np.pi * expected, rtol=1e-6)


def test_boxes_cast_shadows_from_the_sun():
    ground = scenes.Scene("ground", np.array([[-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2]], float),
                          np.array([[0, 2, 1], [0, 3, 2]]), 0.5, 0.0, 0, ("ground",))
    blocker = box(half_size=0.5, centre=(0, 1.5, 0), albedo=0.5)
    scene = scenes.Scene.concatenate("shadow", [ground, blocker], sun=scenes.DirectionalLight([0, 1, 0], [1, 1, 1]))
    voxels = voxelize(scene, 24)
    e = transport.solve(voxels, scene.sun).irradiance[:, 0]
    on_ground = voxels.position[:, 1] < 0.05
    under = on_ground & (np.abs(voxels.position[:, [0, 2]]).max(axis=1) < 0.35)
    open_ground = on_ground & (np.abs(voxels.position[:, [0, 2]]).max(axis=1) > 0.8)
    assert e[under].max() < 0.05 and e[open_ground].min() > 0.95
