"""Probe grid: projection, validity inside solids, interpolation and texture packing."""

import numpy as np
import pytest

from viewer import gi, probes, sh, transport
from viewer import scene as scenes
from viewer.probes import ProbeGrid, fill_invalid
from viewer.raymarch import Tracer
from viewer.voxels import voxelize
from scenes import box, lit_room


def random_grid(m=4, seed=0):
    rng = np.random.default_rng(seed)
    return ProbeGrid(lo=[-1, -1, -1], hi=[1, 1, 1], coefficients=rng.normal(size=(m, m, m, 9, 3)),
                     valid=np.ones((m, m, m), bool))


def test_interpolation_hits_probe_centres_and_is_linear_between_them():
    grid = random_grid()
    centres = grid.positions.reshape(-1, 3)
    assert np.allclose(grid.interpolate(centres), grid.coefficients.reshape(-1, 9, 3), atol=1e-6)
    a, b = grid.positions[1, 2, 1], grid.positions[2, 2, 1]
    mid = grid.interpolate((0.25 * a + 0.75 * b)[None])[0]
    assert np.allclose(mid, 0.25 * grid.coefficients[1, 2, 1] + 0.75 * grid.coefficients[2, 2, 1], atol=1e-5)


def test_interpolation_clamps_at_the_outer_probes_like_a_clamped_texture():
    grid = random_grid()
    corner = grid.positions[0, 0, 0]
    outside = np.array([[-1.0, -1.0, -1.0], [-5.0, -5.0, -5.0]])
    assert np.allclose(grid.interpolate(outside), grid.coefficients[0, 0, 0], atol=1e-6)
    assert np.allclose(grid.interpolate(corner[None]), grid.coefficients[0, 0, 0], atol=1e-6)


def test_texture_packing_keeps_27_coefficients_per_probe_in_gl_order():
    grid = random_grid(m=3)
    volumes = grid.texture_data()
    assert len(volumes) == 7 and all(v.shape == (3, 3, 3, 4) for v in volumes)
    flat = np.concatenate(volumes, axis=-1)[..., :27]           # [z, y, x, 27]
    x, y, z = 2, 0, 1
    assert np.allclose(flat[z, y, x].reshape(9, 3), grid.coefficients[x, y, z])


def test_fill_invalid_takes_the_mean_of_valid_neighbours_and_never_wraps():
    c = np.zeros((4, 4, 4, 9, 3))
    valid = np.ones((4, 4, 4), bool)
    c[0, :, :] = 1.0
    c[3, :, :] = 100.0
    valid[3, 1, 1] = False
    filled = fill_invalid(c, valid)
    # neighbours of (3,1,1): (2,1,1)=0, (3,0,1)=(3,2,1)=(3,1,0)=(3,1,2)=100; never (0,1,1) = 1 by wrap-around
    assert filled[3, 1, 1, 0, 0] == pytest.approx((0 + 4 * 100) / 5)


def test_probes_inside_a_solid_box_are_invalid_and_filled_from_outside():
    scene = lit_room(box(half_size=0.45, albedo=0.5, name="block"))
    grid = gi.solve(scene, gi.GISettings(voxels=16, probes=8, directions=256))
    inside = np.all(np.abs(grid.positions) < 0.45, axis=-1)
    assert inside.sum() == 4 ** 3
    assert not grid.valid[inside].any() and grid.valid[~inside].all()
    dc = grid.coefficients[..., 0, 0]
    # filled from the lit room around it: not black, and never brighter than the room
    assert dc[inside].min() > 0.5 * dc[~inside].min()
    assert dc[inside].max() <= dc[~inside].max()


def test_emitters_light_only_their_front_side():
    """A one-sided emitting square facing up: a probe above sees it, a probe below does not."""
    quad = scenes.Scene("lamp", np.array([[-0.5, 0, -0.5], [0.5, 0, -0.5], [0.5, 0, 0.5], [-0.5, 0, 0.5]], float),
                        np.array([[0, 2, 1], [0, 3, 2]]), 0.0, 1.0, 0, ("lamp",))
    voxels = voxelize(quad, 8)
    light = transport.solve(voxels)
    points = np.array([[0.0, 0.3, 0.0], [0.0, -0.3, 0.0]])
    above, below = probes._emitter_sh(voxels, light, points, Tracer.build(voxels))
    assert above[0, 0] > 0.1 and np.allclose(below, 0)
    # the light comes from below the upper probe: the Y_1,-1 (y) coefficient is negative
    assert above[1, 0] < 0


def test_small_emitter_solid_angle_matches_the_analytic_disc():
    """On-axis irradiance from a square lamp of side s at distance d, through SH: within 3% of the
    exact value of a square (E = 4 L arctan-formula), i.e. the fine light samples resolve it."""
    s, d, radiance = 0.4, 0.25, 3.0
    quad = scenes.Scene("lamp", np.array([[-s / 2, 0, -s / 2], [s / 2, 0, -s / 2], [s / 2, 0, s / 2],
                                          [-s / 2, 0, s / 2]], float),
                        np.array([[0, 1, 2], [0, 2, 3]]), 0.0, radiance, 0, ("lamp",))  # faces down
    voxels = voxelize(quad, 16)
    light = transport.solve(voxels)
    coefficients = probes._emitter_sh(voxels, light, np.array([[0.0, -d, 0.0]]), Tracer.build(voxels))
    e_sh = sh.irradiance(coefficients[0], np.array([0.0, 1.0, 0.0]))[0]
    a = s / 2 / d  # exact irradiance under the centre of a square: 4 L (a / sqrt(1+a^2)) atan(a / sqrt(1+a^2))
    exact = 4 * radiance * (a / np.sqrt(1 + a * a)) * np.arctan(a / np.sqrt(1 + a * a))
    # the L2 SH of a lamp seen under a wide cone blurs it slightly; compare the DC-free irradiance sum
    assert e_sh == pytest.approx(exact, rel=0.05)
