"""glTF as the specification and the Khronos sample models define it: each sample in tests/data/gltf/ (their
sources and licences are in its README.md) loads into the geometry, colours and camera the spec says, and
what the viewer does not read is refused or skipped in one line that names it."""

from __future__ import annotations

import base64
import json
import math
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest

from viewer.scene import SceneError, load
from viewer.scene.camera import home_camera

SAMPLES = Path(__file__).resolve().parent.parent / "data" / "gltf"
WHITE = 0.999   # glTF's default material is white; Scene keeps albedo just below 1 (the bounces converge)


def corners(scene) -> np.ndarray:
    """The distinct vertex positions the faces use."""
    return np.unique(scene.vertices[scene.faces].reshape(-1, 3), axis=0)


def buffer_bytes(document: dict, index: int = 0) -> bytes:
    return base64.b64decode(document["buffers"][index]["uri"].split(",", 1)[1])


def sample(name: str) -> dict:
    return json.loads((SAMPLES / f"{name}.gltf").read_text())


def write(path: Path, document: dict) -> Path:
    path.write_text(json.dumps(document))
    return path


# ---- geometry --------------------------------------------------------------------------------------------

def test_sparse_accessor_raises_three_vertices_of_the_top_row():
    """SimpleSparseAccessor: 14 vertices in two rows (y = 0 and 1); the sparse accessor replaces vertices 8,
    10 and 12 with (1, 2), (3, 3), (5, 4)."""
    s = load(SAMPLES / "SimpleSparseAccessor.gltf")
    assert len(s.faces) == 12
    top = {tuple(p) for p in corners(s) if p[1] > 0}
    assert top == {(0, 1, 0), (1, 2, 0), (2, 1, 0), (3, 3, 0), (4, 1, 0), (5, 4, 0), (6, 1, 0)}


def test_every_triangle_mode_makes_the_same_hexagon_facing_plus_z(capsys):
    """MeshPrimitiveModes: TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN each cover the unit hexagon (area
    about 2.6), wound counter-clockwise seen from +z; POINTS and the three LINE modes have no surface
    and are skipped in one line."""
    s = load(SAMPLES / "MeshPrimitiveModes.gltf")
    assert len(s.faces) == 6 + 4 + 6
    np.testing.assert_allclose(s.face_normals, np.tile([0.0, 0.0, 1.0], (16, 1)), atol=1e-6)
    centres = s.triangles.mean(axis=1)
    assert np.all(centres[:, 1] < -2.0)   # only the bottom row of nodes (translated to y = -3) is triangles
    hexagon = 6 * 0.5 * 1.0 * 0.866   # six triangles about the centre: sides of 1, 0.866 from the centre
    for x in (-2.0, 0.0, 2.0):
        mine = np.abs(centres[:, 0] - x) < 1.0
        assert s.face_areas[mine].sum() == pytest.approx(hexagon, rel=1e-3), x
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "POINTS" in err[0] and "LINE_STRIP" in err[0] and "4 primitive" in err[0], err


def test_strip_and_fan_winding_follows_the_spec(tmp_path):
    """A strip's odd triangles swap their first two vertices' successors (v1, v3, v2), a fan's turn about
    v0: a square as a strip of 4 vertices and as a fan of 4, both seen counter-clockwise from +z."""
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    document = {"asset": {"version": "2.0"}, "nodes": [{"mesh": 0}, {"mesh": 1, "translation": [3, 0, 0]}],
                "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "mode": 5}]},
                           {"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": 6}]}],
                "buffers": [{"uri": "data:application/octet-stream;base64,"
                             + base64.b64encode(positions.tobytes() + np.array([0, 1, 3, 2], np.uint16).tobytes()).decode(),
                             "byteLength": 56}],
                "bufferViews": [{"buffer": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 8}],
                "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
                              {"bufferView": 1, "componentType": 5123, "count": 4, "type": "SCALAR"}]}
    s = load(write(tmp_path / "square.gltf", document))
    assert len(s.faces) == 4
    np.testing.assert_allclose(s.face_normals, np.tile([0.0, 0.0, 1.0], (4, 1)), atol=1e-6)
    np.testing.assert_allclose(s.face_areas, 0.5)


def test_default_morph_weights_move_the_apex_to_y_1_5():
    """SimpleMorph: base triangle (0,0) (1,0) (0.5,0.5); mesh weights (0.5, 0.5) of two targets that each
    lift the apex by 1: p0 + sum w_i d_i puts it at y = 0.5 + 0.5 + 0.5 = 1.5."""
    s = load(SAMPLES / "SimpleMorph.gltf")
    np.testing.assert_allclose(s.vertices[s.faces[0]], [[0, 0, 0], [1, 0, 0], [0.5, 1.5, 0]], atol=1e-6)


def test_node_weights_override_the_mesh_weights(tmp_path):
    document = sample("SimpleMorph")
    document["nodes"][0]["weights"] = [0.0, 0.0]
    s = load(write(tmp_path / "rest.gltf", document))
    np.testing.assert_allclose(s.vertices[s.faces[0]], [[0, 0, 0], [1, 0, 0], [0.5, 0.5, 0]], atol=1e-6)


def test_interleaved_buffer_view_reads_positions_at_their_stride(tmp_path):
    """BoxInterleaved: NORMAL and POSITION share one buffer view with byteStride 24; given its buffer,
    the faces use the positions (at offset 12 of each 24 bytes) moved by the root node's matrix."""
    positions = np.random.default_rng(1).uniform(-0.5, 0.5, (24, 3)).astype(np.float32)
    normals = np.full((24, 3), 7.0, np.float32)
    interleaved = np.concatenate([normals, positions], axis=1).tobytes()
    indices = np.concatenate([np.arange(24), np.arange(12)]).astype(np.uint16).tobytes()
    shutil.copy(SAMPLES / "BoxInterleaved.gltf", tmp_path)
    (tmp_path / "Box_Interleaved.bin").write_bytes(interleaved + indices)
    s = load(tmp_path / "BoxInterleaved.gltf")
    assert len(s.faces) == 12
    matrix = np.array(sample("BoxInterleaved")["nodes"][0]["matrix"]).reshape(4, 4).T   # column-major
    np.testing.assert_allclose(corners(s), np.unique(positions @ matrix[:3, :3].T, axis=0), atol=1e-6)
    np.testing.assert_allclose(s.albedo, np.tile([0.8, 0.0, 0.0], (12, 1)), atol=1e-6)


# ---- materials -------------------------------------------------------------------------------------------

def test_vertex_colours_multiply_the_base_colour_per_face():
    """BoxVertexColors: albedo = baseColorFactor (0.8 grey) x COLOR_0 (float RGBA), averaged per face."""
    document = sample("BoxVertexColors")
    raw = buffer_bytes(document)
    indices = np.frombuffer(raw[:72], np.uint16).reshape(-1, 3)
    colours = np.frombuffer(raw[648:1032], np.float32).reshape(-1, 4)[:, :3]
    s = load(SAMPLES / "BoxVertexColors.gltf")
    expected = 0.800000011920929 * colours[indices].mean(axis=1)
    np.testing.assert_allclose(s.albedo, np.clip(expected, 0, WHITE), atol=1e-6)
    assert np.ptp(s.albedo, axis=0).max() > 0.3   # the faces differ: the colours were read


def test_a_primitive_without_a_material_is_white():
    s = load(SAMPLES / "SimpleSparseAccessor.gltf")
    np.testing.assert_allclose(s.albedo, WHITE)
    assert not s.emission.any()


# ---- cameras ---------------------------------------------------------------------------------------------

def test_the_first_perspective_camera_is_the_opening_view():
    """Cameras: a perspective camera (yfov 0.7 rad) at (0.5, 0.5, 3) looking along -Z, and an orthographic
    one, which the pinhole viewer does not use."""
    path = SAMPLES / "Cameras.gltf"
    s = load(path)
    assert len(s.cameras) == 1 and s.camera == s.cameras[0]
    assert s.camera.fov == pytest.approx(math.degrees(0.7))
    np.testing.assert_allclose(s.camera.origin, [0.5, 0.5, 3.0])
    view = np.subtract(s.camera.target, s.camera.origin)
    np.testing.assert_allclose(view / np.linalg.norm(view), [0, 0, -1], atol=1e-9)
    np.testing.assert_allclose(s.camera.up, [0, 1, 0], atol=1e-9)
    assert home_camera(s, path) == s.camera


def test_a_camera_node_s_rotation_turns_the_view(tmp_path):
    document = sample("Cameras")
    document["nodes"][1]["rotation"] = [0.0, math.sin(math.pi / 4), 0.0, math.cos(math.pi / 4)]   # 90 deg about y
    s = load(write(tmp_path / "turned.gltf", document))
    view = np.subtract(s.camera.target, s.camera.origin)
    np.testing.assert_allclose(view / np.linalg.norm(view), [-1, 0, 0], atol=1e-9)


def test_a_sidecar_camera_overrides_the_file_s(tmp_path):
    path = write(tmp_path / "cams.gltf", sample("Cameras"))
    (tmp_path / "cams.json").write_text(json.dumps({"camera": {"origin": [0, 0, 9], "target": [0, 0, 0]}}))
    s = load(path)
    assert s.camera.origin == (0.0, 0.0, 9.0) and home_camera(s, path) == s.camera


# ---- what the viewer does not read -------------------------------------------------------------------------

def test_a_missing_buffer_is_named_as_missing():
    with pytest.raises(SceneError) as refused:
        load(SAMPLES / "BoxInterleaved.gltf")
    message = str(refused.value)
    assert "'Box_Interleaved.bin' is missing" in message and "\n" not in message, message


@pytest.mark.parametrize("extension", ["KHR_draco_mesh_compression", "EXT_meshopt_compression"])
def test_a_required_extension_the_viewer_does_not_read_is_refused_by_name(tmp_path, extension):
    """Box (Draco) declares KHR_draco_mesh_compression required: its accessors hold no data of their own."""
    document = sample("SimpleSparseAccessor")
    document["extensionsUsed"] = document["extensionsRequired"] = [extension]
    with pytest.raises(SceneError) as refused:
        load(write(tmp_path / "compressed.gltf", document))
    message = str(refused.value)
    assert extension in message and "\n" not in message, message


def test_a_required_extension_the_viewer_reads_is_accepted(tmp_path):
    document = sample("SimpleSparseAccessor")
    document["extensionsRequired"] = ["KHR_mesh_quantization", "KHR_materials_emissive_strength"]
    assert len(load(write(tmp_path / "fine.gltf", document)).faces) == 12


def test_a_glb_buffer_without_uri_is_the_binary_chunk(tmp_path):
    """The same sparse sample as a GLB: buffer 0 without a uri is the file's BIN chunk."""
    document = sample("SimpleSparseAccessor")
    binary = buffer_bytes(document)
    del document["buffers"][0]["uri"]
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(binary), b"BIN\0") + binary
    (tmp_path / "sparse.glb").write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks)
    assert {(5.0, 4.0, 0.0), (3.0, 3.0, 0.0)} <= {tuple(p) for p in corners(load(tmp_path / "sparse.glb"))}


# ---- lights ----------------------------------------------------------------------------------------------

def lamp_gltf(path: Path, light: dict, position) -> Path:
    """A 4 x 4 floor at y = 0 facing up, and one KHR_lights_punctual light at `position`."""
    floor = np.array([[-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2]], np.float32)
    indices = np.array([0, 3, 2, 0, 2, 1], np.uint16)
    binary = floor.tobytes() + indices.tobytes()
    document = {"asset": {"version": "2.0"}, "extensionsUsed": ["KHR_lights_punctual"],
                "scene": 0, "scenes": [{"nodes": [0, 1]}],
                "nodes": [{"mesh": 0}, {"translation": list(map(float, position)),
                                        "extensions": {"KHR_lights_punctual": {"light": 0}}}],
                "meshes": [{"name": "floor", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
                "extensions": {"KHR_lights_punctual": {"lights": [light]}},
                "buffers": [{"uri": "data:application/octet-stream;base64," + base64.b64encode(binary).decode(),
                             "byteLength": len(binary)}],
                "bufferViews": [{"buffer": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 12}],
                "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
                              {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}]}
    return write(path, document)


def test_a_point_light_is_a_small_closed_sphere_of_the_same_power(tmp_path):
    """A Lambertian emitter of radiance L and area A sends pi L A; an isotropic point light of intensity I
    sends 4 pi I: the sphere that stands for it sends the same, from around the light's position."""
    s = load(lamp_gltf(tmp_path / "lamp.gltf", {"type": "point", "name": "bulb", "color": [1.0, 0.5, 0.25],
                                                "intensity": 8.0}, [0.5, 1.0, 0.0]))
    bulb = s.face_group == s.group_index("bulb")
    corners = s.vertices[s.faces[bulb]].reshape(-1, 3)
    size = np.linalg.norm([4.0, 0.0, 4.0])
    np.testing.assert_allclose(np.linalg.norm(corners - [0.5, 1.0, 0.0], axis=1), 0.005 * size, rtol=1e-6)
    power = np.pi * (s.emission[bulb] * s.face_areas[bulb, None]).sum(axis=0)
    np.testing.assert_allclose(power, 4 * np.pi * 8.0 * np.array([1.0, 0.5, 0.25]), rtol=1e-9)
    centre = corners.mean(axis=0)   # every face seen from outside: the normals point away from the centre
    assert np.all(np.einsum("ij,ij->i", s.face_normals[bulb], s.triangles[bulb].mean(axis=1) - centre) > 0)
    assert np.all(s.albedo[bulb] == 0)


def test_draco_primitives_without_their_own_data_are_refused_even_when_not_declared_required(tmp_path):
    """A file that lists KHR_draco_mesh_compression as used only, yet leaves its positions to Draco (an
    accessor without a buffer view): the positions would read as zeros, so it is refused by name."""
    document = sample("Cameras")
    document["extensionsUsed"] = ["KHR_draco_mesh_compression"]
    document["meshes"][0]["primitives"][0]["extensions"] = {
        "KHR_draco_mesh_compression": {"bufferView": 0, "attributes": {"POSITION": 0}}}
    del document["accessors"][1]["bufferView"]
    with pytest.raises(SceneError, match="KHR_draco_mesh_compression"):
        load(write(tmp_path / "draco.gltf", document))
