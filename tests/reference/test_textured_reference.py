"""Mitsuba sees the textures the viewer shows: a textured glTF's reflectance in the ground truth at a point
is the albedo the viewer's voxels and renderer take there (texture coordinates, transform, wrap modes)."""

from __future__ import annotations

import numpy as np
import pytest

from textured import checker_quad
from viewer.scene import load
from viewer.scene.textures import surface_albedo

pytest.importorskip("viewer.reference.mitsuba")
pytest.importorskip("mitsuba")

POINTS = np.array([[-0.5, 0.5], [0.5, 0.5], [-0.5, -0.5], [0.5, -0.5], [-0.9, 0.1], [0.3, -0.85]])
"""Points (x, y) of the quad z = 0: its quarters' centres and two near the edges (the filter and wrap)."""


def mitsuba_albedo(scene, points) -> np.ndarray:
    """The diffuse reflectance Mitsuba's BSDF gives where rays down the -z axis hit the quad."""
    from viewer.reference.conversion import load_scene
    from viewer.reference.runtime import loaded

    mi, _, _ = loaded()
    loaded_scene = load_scene(scene)
    origin = mi.Point3f(mi.Float(points[:, 0]), mi.Float(points[:, 1]), mi.Float(np.full(len(points), 2.0)))
    hit = loaded_scene.ray_intersect(mi.Ray3f(origin, mi.Vector3f(0.0, 0.0, -1.0)))
    return np.array(hit.bsdf().eval_diffuse_reflectance(hit)).reshape(3, -1).T


def viewer_albedo(scene, points) -> np.ndarray:
    """surface_albedo at the points, found by their barycentric weights in the quad's triangles."""
    out = []
    for p in points:
        for f, (a, b, c) in enumerate(scene.triangles[:, :, :2]):
            v, w = np.linalg.solve(np.column_stack([b - a, c - a]), p - a)
            if v >= -1e-9 and w >= -1e-9 and v + w <= 1 + 1e-9:
                out.append(surface_albedo(scene, [f], [[1 - v - w, v, w]])[0])
                break
    return np.array(out)


@pytest.mark.parametrize("options", [
    {}, {"transform": {"offset": [0.25, 0.5], "rotation": 0.392699, "scale": [1.5, 1.5]}},
    {"wrap": (33648, 33648), "uv": np.array([[1.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 1.0]])},
    {"wrap": (33071, 33071), "uv": np.array([[-0.5, 0.0], [1.5, 0.0], [1.5, 1.0], [-0.5, 1.0]])},
    {"factor": (0.5, 0.8, 1.0, 1.0)}, {"mag_filter": 9728}])
def test_mitsuba_reflects_the_texture_the_viewer_shows(tmp_path, options):
    scene = load(checker_quad(tmp_path / "checker.gltf", **options))
    assert scene.textured
    np.testing.assert_allclose(mitsuba_albedo(scene, POINTS), viewer_albedo(scene, POINTS), atol=2e-3)


def test_the_reference_cache_tells_textured_scenes_apart(tmp_path):
    """The same triangles and mean colours with another texture position are another ground truth."""
    from viewer.reference import cache

    plain = load(checker_quad(tmp_path / "plain.gltf"))
    moved = load(checker_quad(tmp_path / "moved.gltf", transform={"offset": [0.5, 0.0]}))
    assert cache.key("t", plain, [], {}) != cache.key("t", moved, [], {})
