"""The probes' visibility of a ray end swept over the lattice (viewer/rays/lattice_sight.py): the answers
of every segment traced, but for a few pairs in ten thousand, for a fraction of the rays; walls thinner
than a lattice cell stop it; a move keeps what it cannot change."""

import numpy as np
import pytest

from viewer.bench.stability import scenes as rooms
from viewer.neural import encoding
from viewer.neural.lattice import moved_box
from viewer.probes.grid import ProbeGrid
from viewer.rays import cast
from viewer.rays.lattice_sight import SEED_CELLS, LatticeSight
from viewer.rays.voxels import voxelize
from viewer.scene import load

pytestmark = pytest.mark.skipif(not cast.embree_available(), reason="the sweep traces through Embree")
VOXELS = 32


def swept(scene, m: int, previous=None):
    """(occluders, probe points, their sight) of `scene` on an m^3 lattice over its bounds."""
    lo, hi = scene.bounds
    blockers = encoding.Occluders(scene, voxelize(scene, VOXELS), "embree")
    points = ProbeGrid.positions_for(lo, hi, m).reshape(-1, 3)
    box = None if previous is None else moved_box(previous.blockers, blockers)
    return blockers, points, LatticeSight(blockers, points, lo, (hi - lo) / m, previous, box)


def lamp_ends(scene, blockers, m: int) -> np.ndarray:
    """The ends of the lamps' visibility rays (`encoding.shadow_targets`) on an m^3 lattice."""
    lo, hi = scene.bounds
    voxels = voxelize(scene, VOXELS)
    spacing = (hi - lo) / m
    position, normal, _, _ = encoding.emitting_patches(encoding.lattice_cells(voxels.position, lo, spacing, m),
                                                       voxels)
    return encoding.shadow_targets(blockers, position, normal, lo, spacing)[0]


@pytest.mark.parametrize("name", ["cornell", "thin-shelf", "two-rooms-door"])
def test_the_sweep_gives_every_segments_answer_but_a_few_in_ten_thousand(name):
    """Against `VoxelRays.pairs_clear` of every probe and ray end (the lamp's, and points on the floor
    that the boxes, the shelf or the wall hide from most probes): each segment the sweep traced has its
    own answer, and all but a few pairs in ten thousand agree, from a fifth of the rays or fewer."""
    scene = {"cornell": lambda: load("cornell"), "thin-shelf": rooms.thin_shelf,
             "two-rooms-door": lambda: rooms.two_rooms(door=True)}[name]()
    blockers, points, sight = swept(scene, 24)
    lo, hi = scene.bounds
    floor = lo + (hi - lo) * np.array([[0.3, 0.02, 0.3], [0.7, 0.02, 0.6], [0.5, 0.02, 0.85], [0.15, 0.5, 0.5]])
    ends = np.concatenate([lamp_ends(scene, blockers, 24), floor])
    exact = blockers.pairs_clear(points, ends).T
    out, traced, count = sight.visibility(ends)
    assert count == traced.sum()
    assert np.array_equal(out[traced], exact[traced])
    assert np.isin(out, (0.0, 1.0)).all()
    assert np.mean(out != exact) < 5e-4
    assert count < 0.2 * exact.size
    assert 0.05 < exact.mean() < 0.95   # shadows to sweep across


def test_a_wall_thinner_than_a_cell_hides_the_lamp_from_the_whole_dark_room():
    """Two rooms split by a wall 0.02 thick (a twelfth of a lattice cell), no doorway: no probe on the
    dark side sees any end of the lamp's rays, as no segment through the wall does."""
    scene = rooms.two_rooms(door=False)
    blockers, points, sight = swept(scene, 24)
    ends = lamp_ends(scene, blockers, 24)
    out, _, _ = sight.visibility(ends)
    dark = rooms.in_dark_room(points)
    assert dark.sum() > 0.4 * len(points)
    assert not out[:, dark].any()
    assert out[:, ~dark].mean() > 0.5
    assert np.array_equal(out, blockers.pairs_clear(points, ends).T)


def test_in_an_empty_room_only_the_probes_near_the_end_are_traced():
    """Nothing between the probes and the end: every probe sees it, and only the probes within
    SEED_CELLS of its lattice point trace a segment."""
    scene = rooms.room()
    blockers, points, sight = swept(scene, 16)
    end = np.array([[0.1, 0.3, -0.2]])
    out, traced, count = sight.visibility(end)
    assert out.all()
    assert count == (2 * SEED_CELLS + 1) ** 3


def test_after_a_move_the_kept_edges_and_segments_give_the_fresh_sweep():
    """A moved box: the sight made from the previous one (its lattice edges kept outside the box around
    the moved triangles, the segments it traced there too) answers every pair as a fresh sweep does,
    tracing a fraction of its segments."""
    scene = load("cornell")
    before_blockers, points, before = swept(scene, 24)
    ends = lamp_ends(scene, before_blockers, 24)
    rows, traced, _ = before.visibility(ends)
    shifted = scene.transformed_group("small-box", np.array([[1, 0, 0, 0.1], [0, 1, 0, 0], [0, 0, 1, 0.1],
                                                             [0, 0, 0, 1.0]]))
    blockers, _, after = swept(shifted, 24, before)
    _, _, fresh = swept(shifted, 24)
    assert np.array_equal(after.clear, fresh.clear)
    assert not np.array_equal(after.clear, before.clear)
    box = moved_box(before_blockers, blockers)
    kept = after.visibility(ends, (*box, rows, traced, np.ones(len(ends), bool)))
    again = fresh.visibility(ends)
    assert np.array_equal(kept[0], again[0]) and np.array_equal(kept[1], again[1])
    assert 0 < kept[2] < 0.5 * again[2]
    assert not np.array_equal(kept[0], rows)
    some = np.arange(len(ends)) % 3 == 0     # the others swept afresh, in among the kept ones
    mixed = after.visibility(ends, (*box, rows, traced, some))
    assert np.array_equal(mixed[0], again[0]) and np.array_equal(mixed[1], again[1])
    assert kept[2] < mixed[2] < again[2]
