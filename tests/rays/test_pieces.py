"""The compiled piece binning (viewer.rays.pieces): the pieces of the 4-way midpoint split, and their
(voxel, face) sums, against the plain construction in numpy."""

import numpy as np
import pytest

from viewer.scene import load
from viewer.evaluation.procedural import PRESETS, random_scene
from viewer.rays.pieces import PIECE_EDGE, face_pairs, piece_centroids
from viewer.rays.voxels import face_facing, grid_frame, subdivide


def midpoint_split_centroids(level: int) -> np.ndarray:
    """Barycentric centroids of a triangle split at its edge midpoints `level` times, recursively."""
    tri = np.eye(3)[None]
    for _ in range(level):
        a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
        ab, bc, ca = 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a)
        tri = np.concatenate([np.stack(s, axis=1) for s in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return tri.mean(axis=1)


@pytest.mark.parametrize("level", range(6))
def test_the_lattice_pieces_are_the_midpoint_split(level):
    ours = piece_centroids(level)
    assert ours.shape == (4 ** level, 3)
    np.testing.assert_allclose(ours.sum(axis=1), 1.0, atol=1e-12)
    key = lambda c: np.lexsort(np.round(c, 9).T[::-1])   # noqa: E731 - sort rows to compare sets
    theirs = midpoint_split_centroids(level)
    np.testing.assert_allclose(ours[key(ours)], theirs[key(theirs)], atol=1e-12)


def numpy_pairs(scene, resolution):
    """Every piece made as a row, binned by np.unique: what the compiled loop sums as it goes."""
    lo, size = grid_frame(scene, resolution)
    facing = face_facing(scene.face_normals)
    centroid, area, face = subdivide(scene.triangles, PIECE_EDGE * size)
    coords = np.clip(np.floor((centroid - lo) / size).astype(np.int64), 0, resolution - 1)
    key = (coords[:, 0] + resolution * (coords[:, 1] + resolution * coords[:, 2])) * 6 + facing[face]
    pair, inverse = np.unique(key * len(scene.faces) + face, return_inverse=True)
    moment = np.stack([np.bincount(inverse.ravel(), centroid[:, c] * area) for c in range(3)], axis=1)
    return pair, np.bincount(inverse.ravel(), area), moment


@pytest.mark.parametrize("name", ["cornell", "paper-test", "v2"])
@pytest.mark.parametrize("resolution", [7, 24, 32])
def test_the_pairs_are_the_pieces_summed(name, resolution):
    scene = (random_scene(np.random.default_rng([14, 3]), "v2", PRESETS["v2"])[0] if name == "v2"
             else load(name))
    lo, size = grid_frame(scene, resolution)
    key, face, area, moment = face_pairs(scene.triangles, scene.face_areas, face_facing(scene.face_normals), lo,
                                         size, resolution)
    pair, their_area, their_moment = numpy_pairs(scene, resolution)
    order = np.argsort(key * len(scene.faces) + face)
    assert np.array_equal((key * len(scene.faces) + face)[order], pair)
    np.testing.assert_allclose(area[order], their_area, rtol=1e-12)
    np.testing.assert_allclose(moment[order], their_moment, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(np.bincount(face, area, minlength=len(scene.faces)), scene.face_areas, rtol=1e-12)
