"""A glTF spot light (KHR_lights_punctual) is its point light's emitting sphere inside a black shade: the
floor in its cone gets the irradiance I cos(theta) / d^2 of a point light, the floor beyond its outer cone
none, as the solver's direct light measures it."""

from __future__ import annotations

import base64
import json
import math
from pathlib import Path

import numpy as np
import pytest

from tests.scenes import CUBE_QUADS, CUBE_VERTICES, quads_to_triangles
from viewer.physical import geometry, lightpaths, relight
from viewer.scene import SceneError, load
from viewer.scene.gltf_lights import cone_angles

LAMP = np.array([0.0, 2.5, 0.0])
DOWN = [-math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)]
"""A node rotation (x, y, z, w) that turns the spot's local -Z to world -Y: a quarter turn about x."""


def spot_room(path: Path, light: dict, rotation=DOWN) -> Path:
    """A closed 4 x 3 x 4 room (faces inward, white) with one KHR_lights_punctual light at LAMP."""
    corners = (CUBE_VERTICES * [2.0, 1.5, 2.0] + [0.0, 1.5, 0.0]).astype(np.float32)
    indices = quads_to_triangles(CUBE_QUADS)[:, ::-1].astype(np.uint16).ravel()
    binary = corners.tobytes() + indices.tobytes()
    document = {"asset": {"version": "2.0"}, "extensionsUsed": ["KHR_lights_punctual"],
                "scene": 0, "scenes": [{"nodes": [0, 1]}],
                "nodes": [{"mesh": 0}, {"translation": LAMP.tolist(), "rotation": list(rotation),
                                        "extensions": {"KHR_lights_punctual": {"light": 0}}}],
                "meshes": [{"name": "room", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
                "extensions": {"KHR_lights_punctual": {"lights": [light]}},
                "buffers": [{"uri": "data:application/octet-stream;base64," + base64.b64encode(binary).decode(),
                             "byteLength": len(binary)}],
                "bufferViews": [{"buffer": 0, "byteLength": corners.nbytes},
                                {"buffer": 0, "byteOffset": corners.nbytes, "byteLength": indices.nbytes}],
                "accessors": [{"bufferView": 0, "componentType": 5126, "count": 8, "type": "VEC3"},
                              {"bufferView": 1, "componentType": 5123, "count": len(indices), "type": "SCALAR"}]}
    path.write_text(json.dumps(document))
    return path


def floor_light(scene, voxels: int) -> tuple[np.ndarray, np.ndarray]:
    """The solver's direct irradiance (mean of RGB) at the floor's voxels, and each one's vector to LAMP."""
    g = geometry.build(scene, geometry.GeometrySettings(voxels=voxels, probes=4))
    lights = lightpaths.build(scene, g)
    direct = relight.direct_irradiance(lights, geometry.sun_paths(g, None), relight.materials(scene, g, lights))
    floor = (g.voxels.normal[:, 1] > 0.99) & (g.voxels.position[:, 1] < 1e-3)
    return direct[floor].mean(axis=1), LAMP - g.voxels.position[floor]


def test_a_spot_lights_the_floor_inside_its_cone_as_a_point_light_and_nothing_beyond(tmp_path):
    """Floor voxels well inside the inner cone (0.3 rad) get I cos / d^2 within 2%; those beyond the outer
    cone (0.5 rad) get none of the lamp's direct light; the penumbra between falls off."""
    intensity, inner, outer = 20.0, 0.3, 0.5
    scene = load(spot_room(tmp_path / "spot.gltf", {"type": "spot", "intensity": intensity,
                                                    "spot": {"innerConeAngle": inner, "outerConeAngle": outer}}))
    direct, to_lamp = floor_light(scene, 16)
    distance = np.linalg.norm(to_lamp, axis=1)
    theta = np.arccos(to_lamp[:, 1] / distance)
    ratio = direct / (intensity * np.cos(theta) / distance ** 2)
    lit, penumbra, dark = theta < inner - 0.05, (theta > inner + 0.05) & (theta < outer - 0.05), theta > outer + 0.05
    assert lit.sum() >= 4 and dark.sum() >= 100
    np.testing.assert_allclose(ratio[lit], 1.0, atol=0.02)
    assert np.all((ratio[penumbra] > 0.02) & (ratio[penumbra] < 0.98)), ratio[penumbra]
    assert np.all(ratio[dark] < 1e-3), ratio[dark].max()


def test_the_shade_is_black_its_own_group_and_opens_along_the_node_s_minus_z(tmp_path):
    """The shade neither emits nor reflects, keeps out of the lamp's group (a lamp edit recolours the
    sphere alone), and its rim, seen from the sphere's centre, lies at the cone's middle angle."""
    scene = load(spot_room(tmp_path / "spot.gltf", {"type": "spot", "name": "can", "intensity": 3.0,
                                                    "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.6}}))
    shade = scene.face_group == scene.group_index("can shade")
    assert shade.sum() > 0 and np.all(scene.albedo[shade] == 0) and np.all(scene.emission[shade] == 0)
    assert np.all(scene.emission[scene.face_group == scene.group_index("can")] > 0)
    corners = scene.vertices[np.unique(scene.faces[shade])] - LAMP
    rim = corners[np.argmin(corners[:, 1])]              # the opening's ring lies lowest: the spot looks down
    angles = np.arccos(-corners[:, 1] / np.linalg.norm(corners, axis=1))
    assert np.isclose(np.arccos(-rim[1] / np.linalg.norm(rim)), 0.4, atol=1e-6)
    assert np.all(angles >= 0.4 - 1e-6)                  # nothing of the shade reaches into the cone
    assert shade.sum() <= 200                            # small beside the sphere's 720 triangles


def test_a_point_light_has_no_shade(tmp_path):
    scene = load(spot_room(tmp_path / "point.gltf", {"type": "point", "name": "bulb"}))
    assert scene.groups == ("room", "bulb")


@pytest.mark.parametrize("spot, expected", [
    ({}, (0.0, math.pi / 4)),                                        # the extension's defaults
    ({"innerConeAngle": 0.5, "outerConeAngle": 0.3}, (0.2997, 0.3)),  # inner not below outer: just below
    ({"innerConeAngle": -1.0, "outerConeAngle": 3.0}, (0.0, math.pi / 2)),
])
def test_cone_angles_default_and_clamp_as_the_extension_says(spot, expected):
    np.testing.assert_allclose(cone_angles(spot), expected, atol=1e-9)


@pytest.mark.parametrize("spot", [{"outerConeAngle": "wide"}, {"innerConeAngle": float("nan")},
                                  {"outerConeAngle": True}, [0.3]])
def test_a_malformed_cone_is_refused_in_one_line(tmp_path, spot):
    path = spot_room(tmp_path / "bad.gltf", {"type": "spot", "spot": spot})
    with pytest.raises(SceneError) as caught:
        load(path)
    assert str(path) in str(caught.value) and "\n" not in str(caught.value)


def test_a_point_light_far_above_the_floor_gives_i_over_d_squared_on_a_fine_grid(tmp_path):
    """At 32 voxels the lamp's sphere spans few patches and the floor lies beyond their far field: each
    curved patch is still summed piece by piece, so the floor straight below gets I cos / d^2 (a patch's
    area times the cosine of its mean normal gave 0.62-0.67 of it)."""
    intensity = 20.0
    scene = load(spot_room(tmp_path / "point.gltf", {"type": "point", "intensity": intensity}))
    direct, to_lamp = floor_light(scene, 32)
    distance = np.linalg.norm(to_lamp, axis=1)
    cosine = to_lamp[:, 1] / distance
    ratio = direct / (intensity * cosine / distance ** 2)
    below = cosine > 0.9
    assert below.sum() > 10
    np.testing.assert_allclose(ratio[below], 1.0, atol=0.02)
    np.testing.assert_allclose(ratio, 1.0, atol=0.05)
