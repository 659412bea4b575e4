"""The network's seen filter stopped at walls (viewer/neural/network_feed.py `WallTaps`): a tap across a
surface takes the probe's own light, as the seen light's own filter (`SeenRays.filtered`) does."""

import numpy as np
import pytest

from viewer import scene as scenes
from viewer.neural import encoding
from viewer.neural.encoder import Encoder
from viewer.neural.network_feed import WallTaps, _walled_taps, encoding_walls, filtered, wall_taps
from viewer.rays.voxels import voxelize


def plain_average(opened: np.ndarray) -> np.ndarray:
    """(passes, 1, M, M, M): the average of the open shares over the 3x3x3 probes around each, the faces
    repeated, at least 1/27: the graph's divisor (`ProbeNet.forward`)."""
    padded = np.pad(opened, ((0, 0), (1, 1), (1, 1), (1, 1)), mode="edge")
    m = opened.shape[1]
    total = sum(padded[:, i:i + m, j:j + m, k:k + m] for i in range(3) for j in range(3) for k in range(3))
    return np.maximum(total / 27.0, 1.0 / 27.0)[:, None]


def test_the_box_kernel_stopped_at_walls_is_the_seen_lights_own_filter():
    scene = scenes.load("cornell")
    voxels = voxelize(scene, 16)
    lo, hi = scene.bounds
    encoder = Encoder(lo, hi, 8)
    inputs = encoder.encode(voxels, scene.sun, encoding.occluders(scene, voxels)).inputs
    walls = wall_taps(encoder.seen)
    assert walls is wall_taps(encoder.seen)   # kept for the same rays
    # the same taps from a plain encoding's links, for callers without the encoder's seen rays
    again = encoding_walls(encoding.encode_scene(scene, 8, 16))
    np.testing.assert_array_equal(again.rows, walls.rows)
    np.testing.assert_array_equal(again.sources, walls.sources)
    assert 0 < len(walls.rows) < 8 ** 3       # the two boxes' faces close links, the open room does not
    box = np.full((9, 27), 1.0 / 27.0, np.float32)
    got = filtered(inputs, encoding.SEEN, box, walls) / plain_average(inputs[:, encoding.OPEN])
    light = np.ascontiguousarray(np.transpose(inputs[:, encoding.SEEN].reshape(3, 9, -1), (2, 1, 0)))
    expected = np.transpose(encoder.seen.filtered(light), (2, 1, 0)).reshape(got.shape)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6)
    plain = filtered(inputs, encoding.SEEN, box) / plain_average(inputs[:, encoding.OPEN])
    changed = np.any(np.abs(plain - got) > 1e-6, axis=(0, 1)).reshape(-1)
    assert set(np.flatnonzero(changed)) <= set(walls.rows.tolist()) and changed.any()


def wall_inputs(m: int = 6, wall: int = 2, seed: int = 3):
    """Inputs lit (seen light 1) up to layer `wall` along x and dark beyond, a wall between `wall` and
    `wall` + 1, and a random positive kernel."""
    rng = np.random.default_rng(seed)
    inputs = np.zeros((1, encoding.CHANNELS, m, m, m), np.float32)
    inputs[:, encoding.SEEN, :wall + 1] = 1.0
    inputs[:, encoding.OPEN] = 1.0
    links = np.ones((3, m, m, m), bool)
    links[0, wall] = False
    return inputs, links, rng.random((9, 27)).astype(np.float32)


def test_a_wall_keeps_the_lit_side_out_of_the_dark_side():
    inputs, links, kernels = wall_inputs()
    walls = WallTaps(links, inputs[0, encoding.OPEN])
    walled = filtered(inputs, encoding.SEEN, kernels, walls)
    plain = filtered(inputs, encoding.SEEN, kernels)
    assert np.all(walled[:, :, 3:] == 0.0)       # nothing crosses the wall
    assert np.all(plain[:, :, 3] > 0.0)          # the plain filter's taps do cross it
    # on the lit side next to the wall every tap takes a lit probe: the kernel's whole sum
    np.testing.assert_allclose(walled[0, :, 2], np.broadcast_to(kernels.sum(axis=1)[:, None, None], (9, 6, 6)),
                               rtol=1e-5)
    np.testing.assert_array_equal(walls.scale, 1.0)   # every probe open: the graph's divisor stays right
    assert sorted(walls.rows.tolist()) == sorted(np.flatnonzero(np.isin(np.arange(6 ** 3) // 36, (2, 3))).tolist())


def test_open_links_change_nothing():
    inputs, links, kernels = wall_inputs()
    links[:] = True
    walls = WallTaps(links, inputs[0, encoding.OPEN])
    assert len(walls.rows) == 0
    np.testing.assert_array_equal(filtered(inputs, encoding.SEEN, kernels, walls),
                                  filtered(inputs, encoding.SEEN, kernels))


def test_the_divisor_follows_the_taps_taken():
    """A probe beside a wall whose far side is closed (open share 0) divides, in the graph, by the plain
    average, which counts those zeros; its taps no longer reach them, and the scale makes the quotient
    the average over the probes the taps took."""
    inputs, links, kernels = wall_inputs()
    inputs[:, encoding.OPEN, 3:] = 0.0
    walls = WallTaps(links, inputs[0, encoding.OPEN])
    box = np.full((9, 27), 1.0 / 27.0, np.float32)
    quotient = filtered(inputs, encoding.SEEN, box, walls) / plain_average(inputs[:, encoding.OPEN])
    np.testing.assert_allclose(quotient[:, :, :3], 1.0, rtol=1e-5)   # the lit probes' own light, unblurred


def test_the_field_stops_its_filter_at_walls(monkeypatch):
    """The neural source feeds its network the walled filter of the geometry it encoded: behind a thin
    wall, where light comes only through a doorway, the dark room gets less of the lit room's light."""
    from viewer.bench.stability.scenes import two_rooms
    from viewer.neural import field as field_module
    from viewer.neural.field import NeuralField

    scene = two_rooms(door=True)
    dark = {}
    for walls_on in (True, False):
        taken = []

        def spy(seen, walls_on=walls_on, taken=taken):
            taken.append(wall_taps(seen) if walls_on else None)
            return taken[-1]

        monkeypatch.setattr(field_module, "wall_taps", spy)
        grid = NeuralField().solve(scene, include_emitted=False)
        assert taken and all((t is not None) == walls_on for t in taken)
        m = grid.coefficients.shape[0]
        dark[walls_on] = float(grid.coefficients[m // 2:, :, :, 0, :].mean())   # x > 0: the dark room
    assert dark[True] < 0.95 * dark[False]


def test_the_shipped_network_gives_the_doorways_dark_room_its_true_light():
    """Behind a thin wall, lit only through a doorway, the shipped network's indirect light in the dark
    room is within 10% of Mitsuba's (the unshadowed gather, which passes through walls, is kept out of
    its reflected light: with it the dark room got 1.24x)."""
    from viewer.bench.stability import scenes as st
    from viewer.evaluation.points import free_space_points
    from viewer.evaluation.truth import truth_sh
    from viewer.neural.field import NeuralField
    from viewer.training.truth import mitsuba_available

    if not mitsuba_available():
        pytest.skip("the truth is Mitsuba's")
    scene = st.two_rooms(door=True)
    points = free_space_points(scene, 250, margin=0.06, seed=2)
    dark = st.in_dark_room(points)
    truth = truth_sh(scene, points, 512, include_emitted=False)
    ours = NeuralField().solve(scene, include_emitted=False).interpolate(points)
    assert 0.9 <= ours[dark][:, 0].mean() / truth[dark][:, 0].mean() <= 1.1


def test_only_the_probes_near_a_closed_link_are_walled_and_they_are_all_found():
    # random walls on a small lattice: the probes whose taps differ, worked out for every probe, are the
    # ones WallTaps finds among those near a closed link, with the same taps and scales
    rng = np.random.default_rng(5)
    m = 7
    links = rng.random((3, m, m, m)) > 0.03
    links[0, -1], links[1, :, -1], links[2, :, :, -1] = True, True, True
    opened = rng.random((m, m, m)).astype(np.float32)
    walled, differs, plain, taken = _walled_taps(links, opened.reshape(-1))
    walls = WallTaps(links, opened)
    np.testing.assert_array_equal(walls.rows, np.flatnonzero(differs))
    np.testing.assert_array_equal(walls.sources, walled[differs])
    np.testing.assert_allclose(walls.scale, np.maximum(plain, 1.0)[differs] / np.maximum(taken, 1.0)[differs])
    assert 0 < len(walls.rows) < m ** 3
    # the probes the taps take, each once and in order, and each tap's place among them: numpy's unique
    cells, places = np.unique(walled[differs], return_inverse=True)
    np.testing.assert_array_equal(walls.cells, cells)
    np.testing.assert_array_equal(walls.local, places.reshape(walls.local.shape))
    assert walls.local.dtype == np.int32
