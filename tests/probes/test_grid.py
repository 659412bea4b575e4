"""Probe grid: projection, validity inside solids, interpolation and texture packing."""

import numpy as np
import pytest

from viewer.physical import gi
from viewer.physical import projection
from viewer.probes import grid as probes
from viewer.probes import sh
from viewer.physical import transport
from viewer import scene as scenes
from viewer.probes.grid import ProbeGrid, fill_invalid
from viewer.rays.raymarch import Tracer
from viewer.rays.voxels import voxelize
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


def test_texture_packing_premultiplies_each_probe_by_its_weight():
    """Invalid probes are stored times INVALID_WEIGHT with the weight in the last alpha, so that a
    trilinear fetch over its alpha is the validity-weighted interpolation (shaders/probe_grid.glsl)."""
    grid = random_grid(m=3)
    valid = np.ones((3, 3, 3), bool)
    valid[2, 0, 1] = False
    grid = ProbeGrid(grid.lo, grid.hi, grid.coefficients, valid)
    flat = np.concatenate(grid.texture_data(), axis=-1)          # [z, y, x, 28]
    assert flat[1, 0, 2, 27] == pytest.approx(probes.INVALID_WEIGHT) and flat[0, 0, 0, 27] == 1.0
    assert np.allclose(flat[1, 0, 2, :27].reshape(9, 3), probes.INVALID_WEIGHT * grid.coefficients[2, 0, 1])


def test_surface_irradiance_without_falloff_is_the_plain_interpolation_off_the_surface():
    grid = random_grid()
    rng = np.random.default_rng(3)
    points = rng.uniform(-0.9, 0.9, (20, 3))
    normals = rng.normal(size=(20, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    offset = 0.5 * grid.spacing.min()
    expected = grid.irradiance(points + offset * normals, normals)
    assert np.allclose(grid.surface_irradiance(points, normals, 0.5, plane_falloff=0.0), expected, atol=1e-5)


def test_surface_irradiance_fades_out_probes_behind_the_surface_and_invalid_ones():
    """A wall at x = -0.2 facing +x, between two probe layers: the layer behind it (x = -0.25) sees
    darkness, the ones in front (x = 0.25, 0.75) radiance 1. Plain interpolation at the normal-offset
    point darkens the wall; the surface lookup keeps within 5% of the front layers. Invalid dark probes
    in front of it are left out the same way by their validity weight alone."""
    m = 4
    c = np.zeros((m, m, m, 9, 3))
    c[2:, :, :, 0, :] = 1.0 / sh.basis(np.array([[0.0, 0.0, 1.0]]))[0, 0]   # uniform radiance 1 for x > 0
    grid = ProbeGrid([-1, -1, -1], [1, 1, 1], c, np.ones((m, m, m), bool))
    point, normal = np.array([[-0.2, 0.1, 0.2]]), np.array([[1.0, 0.0, 0.0]])
    front = np.pi                                                    # E = pi L for uniform radiance
    assert grid.irradiance(point + 0.25 * normal, normal)[0, 0] < 0.65 * front
    assert grid.surface_irradiance(point, normal, 0.5)[0, 0] > 0.95 * front
    # the layer at x = 0.25 dark and invalid: with the plane falloff off, validity alone skips it
    c[2] = 0.0
    valid = np.ones((m, m, m), bool)
    valid[2] = False
    grid = ProbeGrid(grid.lo, grid.hi, c, valid)
    assert grid.irradiance(point + 0.75 * normal, normal)[0, 0] < 0.65 * front
    assert grid.surface_irradiance(point, normal, 1.5, plane_falloff=0.0)[0, 0] > 0.98 * front


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
    above, below = projection._emitter_sh(voxels, light, points, Tracer.build(voxels))
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
    coefficients = projection._emitter_sh(voxels, light, np.array([[0.0, -d, 0.0]]), Tracer.build(voxels))
    e_sh = sh.irradiance(coefficients[0], np.array([0.0, 1.0, 0.0]))[0]
    a = s / 2 / d  # exact irradiance under the centre of a square: 4 L (a / sqrt(1+a^2)) atan(a / sqrt(1+a^2))
    exact = 4 * radiance * (a / np.sqrt(1 + a * a)) * np.arctan(a / np.sqrt(1 + a * a))
    # the L2 SH of a lamp seen under a wide cone blurs it slightly; compare the DC-free irradiance sum
    assert e_sh == pytest.approx(exact, rel=0.05)


def test_one_solve_gives_both_the_sampled_and_the_renderers_probes():
    scene = lit_room(box(half_size=0.3, albedo=0.6, name="block"))
    settings = gi.GISettings(voxels=8, probes=6, directions=64)
    everything, indirect = gi.solve_parts(scene, settings, (True, False))
    np.testing.assert_array_equal(everything.coefficients, gi.solve(scene, settings).coefficients)
    np.testing.assert_array_equal(indirect.coefficients, gi.solve(scene, settings, include_emitted=False).coefficients)
    # the lamp's own light is in the first only: more light at every probe that sees it
    assert (everything.coefficients[..., 0, :] >= indirect.coefficients[..., 0, :] - 1e-6).all()
    assert everything.coefficients[..., 0, :].sum() > 1.5 * indirect.coefficients[..., 0, :].sum()
