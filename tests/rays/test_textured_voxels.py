"""The GI sees textures: a textured face's voxels take the texture where they lie, not the material's
mean, by every path that makes voxel colours (a fresh voxelization, the per-face pairs the physical GI
keeps, the relight's sparse products after a colour edit)."""

from __future__ import annotations

import numpy as np
import pytest

from textured import checker_quad
from viewer.physical.geometry import GeometrySettings, build
from viewer.physical.relight import materials
from viewer.physical import lightpaths
from viewer.rays.voxel_faces import FaceVoxels
from viewer.rays.voxels import voxelize
from viewer.scene import load
from viewer.scene.textures import surface_albedo

QUADRANTS = [(-0.5, 0.5), (0.5, 0.5), (-0.5, -0.5), (0.5, -0.5)]


@pytest.fixture(scope="module")
def checker(tmp_path_factory):
    return load(checker_quad(tmp_path_factory.mktemp("checker") / "checker.gltf"))


def footprint_mean(scene, lo, h, coords) -> np.ndarray:
    """The quad's albedo averaged over the square a voxel column (x, y) covers, on a fine grid of points."""
    x0, y0 = lo[0] + coords[0] * h, lo[1] + coords[1] * h
    s = (np.arange(40) + 0.5) / 40
    x, y = np.meshgrid(np.clip(x0 + s * h, -1, 1), np.clip(y0 + s * h, -1, 1))
    points = np.stack([x.ravel(), y.ravel()], axis=1)
    tri = scene.triangles[:, :, :2]
    out = []
    for p in points:
        for f, (a, b, c) in enumerate(tri):
            v, w = np.linalg.solve(np.column_stack([b - a, c - a]), p - a)
            if v >= -1e-9 and w >= -1e-9 and v + w <= 1 + 1e-9:
                out.append(surface_albedo(scene, [f], [[1 - v - w, v, w]])[0])
                break
    return np.mean(out, axis=0)


@pytest.mark.parametrize("resolution", [8, 16])
def test_the_voxel_under_each_checker_square_takes_its_colour(checker, resolution):
    """Each quarter's voxel is the colour of its checker square (red, green, blue reddest, greenest,
    bluest), its albedo the texture's mean over the voxel's footprint within 1%."""
    grid = voxelize(checker, resolution)
    for quarter, (x, y) in enumerate(QUADRANTS):
        cell = grid.cell_of([[x, y, 0.0]])[0]
        voxel = np.flatnonzero(np.all(grid.coords == cell, axis=1))
        assert len(voxel) == 1
        albedo = grid.albedo[voxel[0]]
        if quarter < 3:
            assert np.argmax(albedo) == quarter and albedo[quarter] > 2 * np.delete(albedo, quarter).max(), albedo
        np.testing.assert_allclose(albedo, footprint_mean(checker, grid.lo, grid.voxel_size, cell), atol=0.01)


def test_every_path_to_voxel_colours_agrees_after_a_colour_edit(checker):
    """The pairs the physical GI keeps, the geometry's sparse products and a fresh voxelization give the
    same voxel albedo, for the scene as loaded and recoloured (its pattern kept around the new colour)."""
    settings = GeometrySettings(voxels=8, probes=4, gather_rays=16, directions=16)
    geometry = build(checker, settings)
    for scene in (checker, checker.with_albedo("checker", (0.1, 0.2, 0.3))):
        fresh = voxelize(scene, 8).albedo
        np.testing.assert_allclose(FaceVoxels.of(scene, 8).voxelization(scene).grid.albedo, fresh, atol=1e-9)
        relit = materials(scene, geometry, lightpaths.build(scene, geometry)).albedo
        np.testing.assert_allclose(relit, fresh, atol=1e-6)
    assert np.ptp(fresh[:, 2]) > 0.3   # the recoloured checker still varies
