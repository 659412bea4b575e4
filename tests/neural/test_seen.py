"""The seen rays' directions: dealt out over the probe lattice so that neighbours share one lattice."""

import numpy as np
import pytest

from viewer.neural import encoding
from viewer.neural.seen import (CHAIN_EVERY, INTERLEAVE, SEED, SEEN_RAYS, interleaved_lattices, lattice_packets,
                                lattice_rays)
from viewer.probes import sh
from viewer.probes.grid import ProbeGrid
from viewer.rays.cast import embree_available
from viewer.rays.voxels import voxelize
from viewer.scene import load


def block(directions: np.ndarray, side: int, corner) -> np.ndarray:
    """The directions of the 3x3x3 block of probes whose lowest corner is `corner`."""
    i, j, k = corner
    grid = directions.reshape(side, side, side, *directions.shape[1:])
    return grid[i:i + INTERLEAVE, j:j + INTERLEAVE, k:k + INTERLEAVE].reshape(-1, 3)


@pytest.mark.parametrize("corner", [(0, 0, 0), (1, 2, 0), (4, 3, 5)])
def test_every_3x3x3_block_of_probes_holds_the_whole_lattice_once(corner):
    """Wherever the block sits (the network's filter is centred on every probe), its 27 probes' rays are
    the 27 x 16 directions of one Fibonacci lattice, each once."""
    side, rays = 8, 16
    directions = interleaved_lattices(side, rays, SEED)
    whole, _ = sh.sphere_directions(INTERLEAVE ** 3 * rays, seed=SEED)
    found = block(directions, side, corner)
    assert found.shape == whole.shape
    # each direction of the whole lattice is met by exactly one of the block's
    nearest = np.argmax(found @ whole.T, axis=1)
    assert np.array_equal(np.sort(nearest), np.arange(len(whole)))
    np.testing.assert_allclose(found, whole[nearest], atol=1e-12)


def test_each_probe_alone_still_looks_all_around():
    """A probe's own 16 directions are a stride through the lattice's bands of equal area: one in each
    sixteenth of the sphere's heights, so even unfiltered a probe is not blind to a side."""
    directions = interleaved_lattices(6, 16, SEED)
    assert np.allclose(np.linalg.norm(directions, axis=-1), 1.0)
    assert np.abs(directions.mean(axis=1)).max() < 0.15   # the mean of 16 spread unit vectors
    # undo the lattice's one turn: then its heights (z) per probe fall one in each of 16 equal bands
    n = INTERLEAVE ** 3 * 16
    turn = np.linalg.lstsq(sh.sphere_directions(n)[0], sh.sphere_directions(n, seed=SEED)[0], rcond=None)[0]
    heights = (directions @ np.linalg.inv(turn))[..., 2]
    bands = np.floor((1.0 - heights) / 2.0 * 16).astype(int)
    assert all(np.array_equal(np.sort(b), np.arange(16)) for b in bands)


def test_a_cubic_lattice_is_interleaved_and_other_point_sets_are_turned_at_random():
    """`lattice_rays` deals out directions over a cubic lattice of probes; any other count of points
    (a few points in a test, a list of free-space points) gets one turned lattice each."""
    cubic, basis, sets = lattice_rays(4 ** 3, 16, SEED)
    np.testing.assert_array_equal(cubic, interleaved_lattices(4, 16, SEED))
    # the probes share INTERLEAVE^3 sets of SH weights: each probe's set is its own directions' basis
    assert basis.shape == (INTERLEAVE ** 3, 9, 16) and sets.shape == (4 ** 3,)
    np.testing.assert_allclose(basis[sets].transpose(0, 2, 1), sh.basis(cubic) * (4 * np.pi / 16), rtol=1e-6,
                               atol=1e-7)
    other, basis, sets = lattice_rays(10, 16, SEED)
    assert other.shape == (10, 16, 3) and basis.shape == (10, 9, 16)
    np.testing.assert_array_equal(sets, np.arange(10))
    assert not np.allclose(other[0], other[1])


@pytest.mark.parametrize("read_back, near", [(None, True), (0.5, False)])
def test_the_seen_bounces_converge_to_the_solvers_probes(monkeypatch, read_back, near):
    """The seen light's bounces (each read back at the voxels from the probes and gathered again) carry
    as much light as the physical solver's probes on the same voxels, within 1.5% in each colour on the
    Cornell box; read back half a voxel out, where the probes nearest a wall see it in half their
    directions, the red fell 4.6% short."""
    from viewer import scene as scenes
    from viewer.neural import bounce, encoding
    from viewer.physical.gi import GISettings, PhysicalGI
    from viewer.probes.grid import ProbeGrid

    if read_back is not None:
        monkeypatch.setattr(bounce, "READ_BACK", read_back)
    m = 24
    scene = scenes.load("cornell")
    lo, hi = scene.bounds
    grid, blockers, direct = encoding.lit_voxels(scene, m)
    rays = encoding.seen_rays(blockers, grid, ProbeGrid.positions_for(lo, hi, m).reshape(-1, 3))
    seen, _ = encoding.seen_light(rays, encoding.Bounce(grid, lo, hi, m), grid.albedo,
                                  (grid.albedo * direct / np.pi).astype(np.float32))
    solver = PhysicalGI(GISettings(voxels=m, probes=m))
    solver.update(scene)
    probes = solver.probe_grid(False)
    assert solver.geometry.voxels.count == grid.count   # the same voxels
    open_ = probes.valid.reshape(-1) & (rays.open > 0.5)
    ratio = seen[open_, 0].sum(axis=0) / probes.coefficients.reshape(-1, 9, 3)[open_, 0].sum(axis=0)
    if near:
        np.testing.assert_allclose(ratio, 1.0, atol=0.015)
    else:
        assert ratio[0] < 0.96


def test_the_rays_gather_each_probes_sum_of_basis_times_radiance():
    """`SeenRays.gathered` is, for every probe, the sum over its rays of the SH weights of the ray's
    direction times the radiance of the voxel it lands on (nothing where it lands on none), on a cubic
    lattice (shared sets) and on loose points (a set a probe), for RGB and for light of other widths
    (gathered three channels at a time)."""
    from viewer import scene as scenes
    from viewer.neural import encoding
    from viewer.neural.seen import SeenRays
    from viewer.probes.grid import ProbeGrid
    from viewer.rays.voxels import voxelize

    scene = scenes.load("cornell")
    voxels = voxelize(scene, 12)
    landing = encoding.occluders(scene, voxels).landing
    lo, hi = scene.bounds
    for channels, points in ((3, ProbeGrid.positions_for(lo, hi, 6).reshape(-1, 3)),
                             (3, lo + (hi - lo) * np.random.default_rng(5).random((7, 3))),
                             (1, ProbeGrid.positions_for(lo, hi, 6).reshape(-1, 3)),
                             (5, ProbeGrid.positions_for(lo, hi, 6).reshape(-1, 3))):
        radiance = np.random.default_rng(4).random((voxels.count, channels)).astype(np.float32)
        padded = np.vstack([radiance, np.zeros((1, channels), np.float32)])
        rays = SeenRays(landing, voxels.count, points, 16)
        _, basis, sets = lattice_rays(len(points), 16, SEED)
        landed = padded[rays.voxel.reshape(len(points), 16)]                   # (P, R, C)
        expected = np.einsum("pbr,prc->pbc", basis[sets].astype(np.float64), landed)
        found = rays.gathered(radiance)
        assert found.shape == (len(points), 9, channels) and np.abs(expected).max() > 0.1
        np.testing.assert_allclose(found, expected, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("corner", [(0, 0, 0), (2, 1, 3)])
def test_the_later_bounces_rays_spread_evenly_over_every_block(corner):
    """The seen light's later bounces gather each probe's first rays alone (one in CHAIN_EVERY): every
    3x3x3 block, which the filter after each gather averages, still takes evenly spread directions, one
    in each of its count of equal-area bands of heights, and each probe's own fall one in each of theirs."""
    side, rays = 8, SEEN_RAYS
    first = interleaved_lattices(side, rays, SEED)[:, :rays // CHAIN_EVERY]
    n = INTERLEAVE ** 3 * rays
    turn = np.linalg.lstsq(sh.sphere_directions(n)[0], sh.sphere_directions(n, seed=SEED)[0], rcond=None)[0]
    found = block(first, side, corner) @ np.linalg.inv(turn)
    count = len(found)
    assert count == INTERLEAVE ** 3 * rays // CHAIN_EVERY
    bands = np.floor((1.0 - found[:, 2]) / 2.0 * count).astype(int)
    assert np.array_equal(np.sort(bands), np.arange(count))
    own = rays // CHAIN_EVERY
    heights = (first @ np.linalg.inv(turn))[..., 2]
    each = np.floor((1.0 - heights) / 2.0 * own).astype(int)
    assert all(np.array_equal(np.sort(b), np.arange(own)) for b in each)
    assert np.abs(first.mean(axis=1)).max() < 0.2


def test_a_later_bounces_gather_takes_the_first_rays_weighted_as_the_whole():
    """`SeenRays.gathered(part=True)`: each probe's first rays alone, each weighted CHAIN_EVERY times its
    share of the whole; over the lattice, light of one radiance on every voxel has the same DC either way
    (to the few rays' noise)."""
    from viewer.neural.seen import SeenRays

    scene = load("cornell")
    voxels = voxelize(scene, 12)
    lo, hi = scene.bounds
    points = ProbeGrid.positions_for(lo, hi, 6).reshape(-1, 3)
    rays = SeenRays(encoding.occluders(scene, voxels).landing, voxels.count, points, SEEN_RAYS)
    radiance = np.random.default_rng(2).random((voxels.count, 3)).astype(np.float32)
    padded = np.vstack([radiance, np.zeros((1, 3), np.float32)])
    _, basis, sets = lattice_rays(len(points), SEEN_RAYS, SEED)
    part = SEEN_RAYS // CHAIN_EVERY
    landed = padded[rays.voxel.reshape(len(points), SEEN_RAYS)[:, :part]]
    expected = CHAIN_EVERY * np.einsum("pbr,prc->pbc", basis[sets][:, :, :part].astype(np.float64), landed)
    np.testing.assert_allclose(rays.gathered(radiance, part=True), expected, rtol=1e-5, atol=1e-6)
    uniform = np.ones((voxels.count, 3), np.float32)
    whole, first = rays.gathered(uniform)[:, 0].sum(), rays.gathered(uniform, part=True)[:, 0].sum()
    assert whole > 0 and abs(first / whole - 1.0) < 0.02


@pytest.mark.parametrize("side", [24, 13])
def test_the_packets_hold_every_ray_once_each_one_direction_from_nearby_probes(side):
    """`lattice_packets`: every ray of the lattice in exactly one packet; a packet's rays share their
    direction (one interleaved subset, one ray of it), and where the lattice holds whole 2x2x2 blocks of
    each subset's stride-3 lattice (a side of 6n), they start within two strides of each other."""
    count, rays = side ** 3, SEEN_RAYS
    packets = lattice_packets(count, rays, SEED)
    flat = packets[packets >= 0]
    assert np.array_equal(np.sort(flat), np.arange(count * rays))
    directions, _, _ = lattice_rays(count, rays, SEED)
    d = directions.reshape(-1, 3)
    probe = np.where(packets >= 0, packets // rays, -1)
    for row, owners in zip(packets[::97], probe[::97]):
        live = row[row >= 0]
        assert np.allclose(d[live], d[live[0]])
        ijk = np.stack(np.unravel_index(owners[owners >= 0], (side,) * 3), 1)
        assert np.ptp(ijk, axis=0).max() <= 2 * INTERLEAVE or side % (2 * INTERLEAVE)


@pytest.mark.skipif(not embree_available(), reason="packets are Embree's")
@pytest.mark.parametrize("name", ["cornell", "paper-test"])
def test_rays_traced_in_packets_meet_what_single_rays_meet(name):
    """The seen rays of a 24^3 lattice, traced a packet of parallel rays at a time, meet the same face at
    the same distance and land on the same voxel as traced one by one."""
    scene = load(name)
    lo, hi = scene.bounds
    voxels = voxelize(scene, 24)
    landing = encoding.occluders(scene, voxels).landing
    points = ProbeGrid.positions_for(lo, hi, 24).reshape(-1, 3)
    directions, _, _ = lattice_rays(len(points), SEEN_RAYS, SEED)
    single = landing.kept_bundle(points, directions)
    packed = landing.kept_bundle(points, directions, packets=lattice_packets(len(points), SEEN_RAYS, SEED))
    for a, b in zip(single[:3], packed[:3]):
        assert np.array_equal(a, b)
    assert single[3] == packed[3] == directions.shape[0] * directions.shape[1]
