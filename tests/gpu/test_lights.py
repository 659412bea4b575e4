"""Light samples on the area emitters (numpy, no GL): they must carry the emitters' whole power."""

from __future__ import annotations

import numpy as np

from viewer.gpu.lights import emitter_samples
from viewer.scene import load


def test_samples_lie_on_the_lamp_and_carry_its_area_and_power():
    scene = load("cornell")
    lamp = np.any(scene.emission > 0, axis=1)
    area = scene.face_areas[lamp].sum()
    samples = emitter_samples(scene, 32)
    assert samples.count == 32
    np.testing.assert_allclose(samples.area.sum(), area, rtol=1e-9)
    np.testing.assert_allclose(samples.power.sum(axis=0), (scene.emission[lamp] * scene.face_areas[lamp, None]).sum(0),
                               rtol=1e-9)
    lo, hi = scene.vertices[scene.faces[lamp]].reshape(-1, 3).min(0), scene.vertices[scene.faces[lamp]].reshape(-1, 3).max(0)
    assert np.all(samples.position >= lo - 1e-9) and np.all(samples.position <= hi + 1e-9)
    np.testing.assert_allclose(samples.normal, np.tile([0.0, -1.0, 0.0], (32, 1)), atol=1e-12)  # facing down
    frames = np.stack([samples.tangent, samples.bitangent, samples.normal], axis=1)
    np.testing.assert_allclose(frames @ frames.transpose(0, 2, 1), np.tile(np.eye(3), (32, 1, 1)), atol=1e-12)


def test_samples_cover_the_lamp_evenly():
    """Stratified: every quarter of the lamp gets a quarter of the samples."""
    scene = load("cornell")
    samples = emitter_samples(scene, 64)
    centre = np.median(samples.position, axis=0)
    quadrant = (samples.position[:, 0] > centre[0]).astype(int) * 2 + (samples.position[:, 2] > centre[2])
    counts = np.bincount(quadrant, minlength=4)
    assert counts.min() >= 12, counts


def test_a_scene_without_emitters_has_no_samples():
    scene = load("cornell")
    dark = scene.with_emission("light", [0.0, 0.0, 0.0])
    assert emitter_samples(dark, 16).count == 0
