"""What a new user's own files meet: a scene nothing lights says so, glTF vertex colours tint the base
colour, the sidecar `scene.json` of a single scene, a sidecar that is not used says why, a dim glTF lamp
gets a hint."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from viewer.scene import load, unlit_warning

TRIANGLE_OBJ = "v 0 0 0\nv 0 0 1\nv 1 0 0\nf 1 2 3\n"
SUN = {"sun": {"direction": [0, 1, 0], "irradiance": [3, 2, 1]}}


def test_a_lit_scene_has_no_unlit_warning():
    assert unlit_warning(load("cornell")) is None


def test_an_unlit_scene_names_every_fix(tmp_path):
    (tmp_path / "room.obj").write_text(TRIANGLE_OBJ)
    message = unlit_warning(load(tmp_path / "room.obj"))
    assert message is not None and "\n" not in message
    for fix in ("no emitter and no sun", "Ke", "emissiveFactor", "room.json", "--sun"):
        assert fix in message, fix


def test_a_sun_lights_a_scene_without_emitters(tmp_path):
    (tmp_path / "room.obj").write_text(TRIANGLE_OBJ)
    (tmp_path / "room.json").write_text(json.dumps(SUN))
    assert unlit_warning(load(tmp_path / "room.obj")) is None


# ---- glTF COLOR_0 --------------------------------------------------------------------------------------

def write_glb(path: Path, colours: np.ndarray | None, material: dict | None) -> Path:
    """One triangle, with COLOR_0 (float VEC3, or normalized unsigned bytes VEC4) and a material."""
    positions = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0]], np.float32)
    indices = np.array([0, 1, 2, 0], np.uint16)
    binary = positions.tobytes() + indices.tobytes()
    attributes = {"POSITION": 0}
    accessors = [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                  "min": [0, 0, 0], "max": [1, 0, 1]},
                 {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}]
    views = [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 6}]
    if colours is not None:
        data = colours.tobytes()
        views.append({"buffer": 0, "byteOffset": len(binary), "byteLength": len(data)})
        byte = colours.dtype == np.uint8
        accessors.append({"bufferView": 2, "componentType": 5121 if byte else 5126, "count": 3,
                          "type": "VEC4" if byte else "VEC3", **({"normalized": True} if byte else {})})
        attributes["COLOR_0"] = 2
        binary += data
    binary += b"\0" * (-len(binary) % 4)
    primitive = {"attributes": attributes, "indices": 1, **({"material": 0} if material else {})}
    document = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
                "meshes": [{"primitives": [primitive]}], "materials": [material] if material else [],
                "buffers": [{"byteLength": len(binary)}], "bufferViews": views, "accessors": accessors}
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    chunks = (struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(binary), b"BIN\0") + binary)
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks)
    return path


BASE = {"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.9, 0.8, 1.0]}}


def test_gltf_vertex_colours_multiply_the_base_colour(tmp_path):
    colours = np.array([[1.0, 0.2, 0.1], [0.5, 0.2, 0.3], [0.0, 0.2, 0.2]], np.float32)
    s = load(write_glb(tmp_path / "tinted.glb", colours, BASE))
    np.testing.assert_allclose(s.albedo, [[0.5 * 0.5, 0.9 * 0.2, 0.8 * 0.2]], atol=1e-6)


def test_gltf_normalized_byte_vertex_colours_are_read_as_linear_0_to_1(tmp_path):
    colours = np.array([[255, 0, 51, 255], [255, 0, 51, 255], [255, 0, 51, 255]], np.uint8)
    s = load(write_glb(tmp_path / "bytes.glb", colours, BASE))
    np.testing.assert_allclose(s.albedo, [[0.5, 0.0, 0.8 * 0.2]], atol=1e-6)


def test_gltf_without_vertex_colours_keeps_the_base_colour(tmp_path):
    s = load(write_glb(tmp_path / "plain.glb", None, BASE))
    np.testing.assert_allclose(s.albedo, [[0.5, 0.9, 0.8]], atol=1e-6)


def test_a_dim_gltf_lamp_gets_a_hint_and_a_strong_one_none(tmp_path, capsys):
    dim = dict(BASE, emissiveFactor=[1.0, 1.0, 1.0])
    load(write_glb(tmp_path / "dim.glb", None, dim))
    hint = capsys.readouterr().err
    assert hint.count("\n") == 1 and "KHR_materials_emissive_strength" in hint, hint
    strong = dict(dim, extensions={"KHR_materials_emissive_strength": {"emissiveStrength": 20.0}})
    load(write_glb(tmp_path / "strong.glb", None, strong))
    assert capsys.readouterr().err == ""


# ---- the sidecar ---------------------------------------------------------------------------------------

def test_scene_json_beside_a_single_scene_is_its_sidecar(tmp_path, capsys):
    (tmp_path / "room.obj").write_text(TRIANGLE_OBJ)
    (tmp_path / "scene.json").write_text(json.dumps({**SUN, "camera": {"origin": [1, 2, 3], "fov": 50}}))
    s = load(tmp_path / "room.obj")
    np.testing.assert_allclose(s.sun.irradiance, (3, 2, 1))
    assert s.camera.origin == (1, 2, 3) and s.camera.fov == 50
    assert capsys.readouterr().err == ""


def test_scene_json_beside_several_scenes_is_not_read_and_says_why(tmp_path, capsys):
    for name in ("a.obj", "b.obj"):
        (tmp_path / name).write_text(TRIANGLE_OBJ)
    (tmp_path / "scene.json").write_text(json.dumps(SUN))
    s = load(tmp_path / "a.obj")
    assert s.sun is None
    err = capsys.readouterr().err
    assert "scene.json" in err and "2 scene files" in err and "a.json" in err
    lines = [line for line in err.splitlines() if "scene.json" in line]
    assert len(lines) == 1


def test_a_named_sidecar_wins_over_scene_json(tmp_path):
    (tmp_path / "room.obj").write_text(TRIANGLE_OBJ)
    (tmp_path / "room.json").write_text(json.dumps({"sun": {"direction": [1, 0, 0], "irradiance": [1, 1, 1]}}))
    (tmp_path / "scene.json").write_text(json.dumps(SUN))
    np.testing.assert_allclose(load(tmp_path / "room.obj").sun.direction, (1, 0, 0))


def test_a_sidecar_key_that_is_not_used_says_so(tmp_path, capsys):
    (tmp_path / "room.obj").write_text(TRIANGLE_OBJ)
    (tmp_path / "room.json").write_text(json.dumps({**SUN, "lights": []}))
    load(tmp_path / "room.obj")
    err = capsys.readouterr().err
    assert "'lights'" in err and "not used" in err


@pytest.mark.parametrize("name", ["cornell", "paper-test"])
def test_the_builtin_scenes_load_without_a_note(name, capsys):
    load(name)
    assert capsys.readouterr().err == ""
