"""The geometry after some faces moved (viewer.physical.retrace): tracing again only the rays a move can change
gives the hits of a full trace, ray for ray, and the physical GI's probes after a lamp move are those of
a solver that traced the moved scene afresh."""

import numpy as np
import pytest

from viewer.physical import geometry
from viewer.physical import retrace
from viewer.physical.gi import GISettings, PhysicalGI
from viewer.scene import load
from viewer.evaluation.procedural import PRESETS, random_scene
from viewer.rays.voxel_faces import FaceVoxels

SETTINGS = geometry.GeometrySettings(voxels=24, probes=12, gather_rays=32, directions=128)


def moved(scene, group, offset):
    matrix = np.eye(4)
    matrix[:3, 3] = offset
    return scene.transformed_group(group, matrix)


def assert_same_geometry(ours, theirs):
    for name in ("voxel_keys", "gather_hits", "probe_hits", "probe_backface", "valid", "fill_waves", "lamp"):
        assert np.array_equal(getattr(ours, name), getattr(theirs, name)), name
    assert (ours.transport != theirs.transport).nnz == 0
    assert ours.key == theirs.key


def retraced(scene, edited):
    """(after_moving's geometry of `edited`, a full trace of the same voxels, after_moving's counts)."""
    pairs = FaceVoxels.of(scene, SETTINGS.voxels)
    before = geometry.trace(scene, pairs.voxelization(scene), SETTINGS)
    voxelization = pairs.moved(edited).voxelization(edited)
    stats = {}
    ours = retrace.after_moving(before, edited, voxelization, stats)
    assert ours is not None
    return ours, geometry.trace(edited, voxelization, SETTINGS), stats


@pytest.mark.parametrize("offset", [(0.0, 0.0, -0.1), (0.15, -0.3, 0.2), (-0.2, -0.9, 0.0)],
                         ids=["along the ceiling", "down and across", "into the room"])
def test_a_moved_lamp_gives_the_hits_of_a_full_trace(offset):
    scene = load("cornell")
    ours, theirs, stats = retraced(scene, moved(scene, "light", offset))
    assert_same_geometry(ours, theirs)
    assert stats["probe_rays"] < 0.1 * stats["probe_total"]     # it did not just trace everything again
    assert stats["probe_rays"] > 0


def test_a_lamp_moved_along_the_ceiling_traces_few_rays_again():
    scene = load("cornell")
    _, _, stats = retraced(scene, moved(scene, "light", (0.0, 0.0, -0.1)))
    assert stats["gather_rays"] < 0.1 * stats["gather_total"]   # the voxels' order is kept
    assert stats["probe_rays"] < 0.05 * stats["probe_total"]


def test_a_moved_object_and_a_changed_listing():
    scene, params = random_scene(np.random.default_rng([14, 1]), "v2", PRESETS["v2"])
    group = params["objects"][0]["kind"] + "-1"
    ours, theirs, stats = retraced(scene, moved(scene, group, (0.05, 0.0, 0.05)))
    assert_same_geometry(ours, theirs)
    assert stats["changed_cells"] > 0


def test_nothing_moved_keeps_every_ray():
    scene = load("cornell")
    ours, theirs, stats = retraced(scene, scene)
    assert_same_geometry(ours, theirs)
    assert stats["gather_rays"] == 0 and stats["probe_rays"] == 0


def test_other_frames_are_traced_afresh():
    scene = load("cornell")
    pairs = FaceVoxels.of(scene, SETTINGS.voxels)
    before = geometry.trace(scene, pairs.voxelization(scene), SETTINGS)
    other = load("paper-test")
    assert retrace.after_moving(before, other, FaceVoxels.of(other, SETTINGS.voxels).voxelization(other)) is None


def test_the_physical_gi_after_a_lamp_move_is_the_moved_scenes():
    settings = GISettings(voxels=24, probes=12, gather_rays=32, directions=128)
    scene = load("cornell")
    edited = moved(scene, "light", (0.1, 0.0, -0.1))
    gi = PhysicalGI(settings)
    gi.update(scene)
    prepared = gi.prepare(edited)
    assert prepared.retraced is not None and prepared.retraced["probe_rays"] < 0.1 * prepared.retraced["probe_total"]
    gi.install(prepared)
    gi.relight(edited)
    fresh = PhysicalGI(settings)
    fresh.update(edited)
    ours, theirs = gi.probe_grid().coefficients, fresh.probe_grid().coefficients
    assert np.abs(ours - theirs).max() <= 1e-4 * np.abs(theirs).max()
