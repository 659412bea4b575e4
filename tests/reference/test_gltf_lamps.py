"""A glTF point light (KHR_lights_punctual), which the viewer turns into a small emitting sphere, lights
the scene as Mitsuba's own `point` emitter of the same intensity does: irradiance I cos(theta) / d^2; a
spot light's sphere, in its black shade, lights only its cone there too."""

from __future__ import annotations

import numpy as np
import pytest

reference = pytest.importorskip("viewer.reference.mitsuba")
pytest.importorskip("mitsuba")

from tests.scene.test_gltf_lights import LAMP as SPOT, spot_room   # noqa: E402
from tests.scene.test_gltf_samples import lamp_gltf   # noqa: E402
from viewer.reference.runtime import loaded           # noqa: E402
from viewer.scene import load                        # noqa: E402

INTENSITY = np.array([10.0, 6.0, 3.0])
LAMP = np.array([0.0, 1.0, 0.0])
POINTS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [-0.5, 0.0, 1.2]])
UP = np.array([0.0, 1.0, 0.0])


def mitsuba_point_irradiance(points: np.ndarray) -> np.ndarray:
    """Irradiance on upward-facing points from Mitsuba's `point` emitter alone (radiant intensity I)."""
    mi, dr, _ = loaded()
    scene = mi.load_dict({"type": "scene", "lamp": {"type": "point", "position": LAMP.tolist(),
                                                      "intensity": {"type": "rgb", "value": INTENSITY.tolist()}}})
    out = []
    for p in points:
        it = dr.zeros(mi.Interaction3f)
        it.p = mi.Point3f(*map(float, p))
        ds, weight = scene.sample_emitter_direction(it, mi.Point2f(0.5, 0.5), False)
        cosine = np.ravel(np.array(ds.d))[1]
        out.append(np.ravel(np.array(weight)) * cosine)
    return np.array(out)


def test_a_point_light_s_sphere_gives_the_irradiance_of_mitsuba_s_point_emitter(tmp_path):
    scene = load(lamp_gltf(tmp_path / "lamp.gltf", {"type": "point", "color": (INTENSITY / 10).tolist(),
                                                    "intensity": 10.0}, LAMP))
    ours = reference.irradiance(scene, POINTS, np.tile(UP, (len(POINTS), 1)), spp=1024, max_depth=2, cache=False)
    d = LAMP - POINTS
    analytic = INTENSITY[None, :] * (d[:, 1] / np.linalg.norm(d, axis=1) ** 3)[:, None]
    np.testing.assert_allclose(mitsuba_point_irradiance(POINTS), analytic, rtol=1e-4)
    np.testing.assert_allclose(ours, analytic, rtol=0.02)


def test_mitsuba_sees_a_spot_s_cone_through_its_shade(tmp_path):
    """The same shaded sphere in Mitsuba: I cos / d^2 inside the inner cone, the falloff in between, nothing
    beyond the outer cone (the light straight from the emitters alone, max_depth=1: no bounce in the room)."""
    inner, outer, intensity = 0.3, 0.5, 20.0
    scene = load(spot_room(tmp_path / "spot.gltf", {"type": "spot", "intensity": intensity,
                                                    "spot": {"innerConeAngle": inner, "outerConeAngle": outer}}))
    theta = np.array([0.0, 0.15, 0.25, 0.4, 0.55, 0.7])
    points = np.stack([SPOT[1] * np.tan(theta), np.full_like(theta, 1e-3), np.zeros_like(theta)], axis=1)
    ours = reference.irradiance(scene, points, np.tile(UP, (len(points), 1)), spp=1024, max_depth=1,
                                cache=False).mean(axis=1)
    ratio = ours / (intensity * np.cos(theta) ** 3 / SPOT[1] ** 2)
    np.testing.assert_allclose(ratio[theta < inner], 1.0, rtol=0.03)
    assert 0.1 < ratio[3] < 0.9 and np.all(ratio[theta > outer] < 1e-3), ratio
