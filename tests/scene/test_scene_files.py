"""Loading scene files: glTF/GLB, PLY, groups, sidecar JSON, and bad input (always a one-line
`SceneError`)."""

import base64
import io
import json
import struct
from pathlib import Path

import numpy as np
import pytest
from scenes import group_faces, srgb_to_linear

from viewer.scene import DirectionalLight, SceneError, load

# ---- glTF / GLB ------------------------------------------------------------------------------------------

SQRT_HALF = np.sqrt(0.5)
SIN_22_5, COS_22_5 = np.sin(np.pi / 8), np.cos(np.pi / 8)


def gltf_document(material: dict, texture_png: bytes | None = None) -> tuple[dict, bytes]:
    """One upward-facing triangle under a node raised by 2, plus a directional light under a node
    rotated -45 deg about x inside a parent rotated 90 deg about y (so its sun points to (1, 1, 0)/sqrt2).
    The buffer has no `uri`: `write_gltf` embeds it."""
    positions = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0]], np.float32)
    uvs = np.array([[0, 0], [0, 1], [1, 0]], np.float32)
    indices = np.array([0, 1, 2, 0], np.uint16)  # padded to 4-byte alignment
    binary = positions.tobytes() + uvs.tobytes() + indices.tobytes()
    document = {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_emissive_strength"],
        "scene": 0, "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"mesh": 0, "translation": [0, 2, 0]},
                  {"rotation": [0, SQRT_HALF, 0, SQRT_HALF], "children": [2]},
                  {"rotation": [-SIN_22_5, 0, 0, COS_22_5],
                   "extensions": {"KHR_lights_punctual": {"light": 0}}}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2,
                                    "material": 0}]}],
        "materials": [material],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "directional", "color": [1.0, 0.9, 0.8], "intensity": 3.0}]}},
        "buffers": [{"byteLength": len(binary)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                        {"buffer": 0, "byteOffset": 36, "byteLength": 24},
                        {"buffer": 0, "byteOffset": 60, "byteLength": 6}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 0, 1]},
                      {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5123, "count": 3, "type": "SCALAR"}],
    }
    if texture_png is not None:
        document["images"] = [{"uri": "data:image/png;base64," + base64.b64encode(texture_png).decode()}]
        document["textures"] = [{"source": 0}]
    return document, binary


def write_gltf(path: Path, material: dict, texture_png: bytes | None = None,
               external_buffer: bool = False) -> Path:
    document, binary = gltf_document(material, texture_png)
    if path.suffix == ".glb":
        text = json.dumps(document).encode()
        text += b" " * (-len(text) % 4)
        chunks = (struct.pack("<I4s", len(text), b"JSON") + text
                  + struct.pack("<I4s", len(binary), b"BIN\0") + binary)
        path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks)
        return path
    if external_buffer:
        path.with_suffix(".bin").write_bytes(binary)
        document["buffers"][0]["uri"] = path.with_suffix(".bin").name
    else:
        document["buffers"][0]["uri"] = ("data:application/octet-stream;base64,"
                                         + base64.b64encode(binary).decode())
    path.write_text(json.dumps(document))
    return path


GLOW = {"name": "glow", "pbrMetallicRoughness": {"baseColorFactor": [0.123, 0.456, 0.789, 1.0]},
        "emissiveFactor": [1.0, 0.5, 0.25],
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}}}


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_gltf_material_becomes_albedo_and_emission(tmp_path, suffix):
    s = load(write_gltf(tmp_path / f"glow{suffix}", GLOW))
    np.testing.assert_allclose(s.albedo, [[0.123, 0.456, 0.789]], atol=1e-6)
    np.testing.assert_allclose(s.emission, [[4.0, 2.0, 1.0]], atol=1e-6)
    assert s.groups == ("glow",)
    np.testing.assert_allclose(s.vertices[:, 1], 2.0)  # the node's translation
    np.testing.assert_allclose(s.face_normals, [[0, 1, 0]], atol=1e-6)


def test_gltf_with_an_external_buffer(tmp_path):
    s = load(write_gltf(tmp_path / "external.gltf", GLOW, external_buffer=True))
    np.testing.assert_allclose(s.triangles[0], [[0, 2, 0], [0, 2, 1], [1, 2, 0]])


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_gltf_base_colour_texture_scales_the_albedo_by_its_mean_linear_colour(tmp_path, suffix):
    from PIL import Image

    pixels = np.array([[[255, 128, 0], [0, 64, 200]]], np.uint8)
    png = io.BytesIO()
    Image.fromarray(pixels).save(png, format="PNG")
    textured = dict(GLOW, pbrMetallicRoughness={"baseColorFactor": [0.5, 0.5, 0.5, 1.0],
                                                "baseColorTexture": {"index": 0}})
    s = load(write_gltf(tmp_path / f"textured{suffix}", textured, png.getvalue()))
    expected = 0.5 * srgb_to_linear(pixels.reshape(-1, 3)).mean(axis=0)
    np.testing.assert_allclose(s.albedo, [expected], rtol=1e-6)


def test_gltf_mirroring_node_turns_the_front_face(tmp_path):
    path = write_gltf(tmp_path / "mirrored.gltf", GLOW)
    document = json.loads(path.read_text())
    document["nodes"][0]["scale"] = [1, -1, 1]
    path.write_text(json.dumps(document))
    np.testing.assert_allclose(load(path).face_normals, [[0, -1, 0]], atol=1e-6)


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_gltf_emissive_strength_applies_to_unnamed_materials(tmp_path, suffix):
    unnamed = {k: v for k, v in GLOW.items() if k != "name"}
    s = load(write_gltf(tmp_path / f"unnamed{suffix}", unnamed))
    np.testing.assert_allclose(s.emission, [[4.0, 2.0, 1.0]], atol=1e-6)


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_gltf_directional_light_becomes_the_sun(tmp_path, suffix):
    s = load(write_gltf(tmp_path / f"sun{suffix}", GLOW))
    assert s.sun is not None
    np.testing.assert_allclose(s.sun.direction, [SQRT_HALF, SQRT_HALF, 0], atol=1e-6)
    np.testing.assert_allclose(s.sun.irradiance, [3.0, 2.7, 2.4], atol=1e-6)


def test_sun_argument_overrides_the_gltf_light(tmp_path):
    sun = DirectionalLight((0, 1, 0), (5, 5, 5))
    s = load(write_gltf(tmp_path / "sun.glb", GLOW), sun=sun)
    np.testing.assert_allclose(s.sun.direction, (0, 1, 0))


# ---- PLY -------------------------------------------------------------------------------------------------

def write_ply(path: Path, colours: list | None, face_colours: list | None = None) -> Path:
    positions = [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)]
    header = ["ply", "format ascii 1.0", "element vertex 4", "property float x", "property float y",
              "property float z"]
    if colours:
        header += ["property uchar red", "property uchar green", "property uchar blue"]
    header += ["element face 2", "property list uchar int vertex_indices"]
    if face_colours:
        header += ["property uchar red", "property uchar green", "property uchar blue"]
    rows = [" ".join(map(str, p + (tuple(colours[i]) if colours else ()))) for i, p in enumerate(positions)]
    faces = [(0, 2, 1), (0, 3, 2)]
    rows += [" ".join(map(str, (3, *f) + (tuple(face_colours[i]) if face_colours else ())))
             for i, f in enumerate(faces)]
    path.write_text("\n".join(header + ["end_header"] + rows) + "\n")
    return path


def test_ply_vertex_colours_become_albedo(tmp_path):
    colours = [(200, 128, 0), (200, 128, 0), (100, 50, 20), (200, 128, 0)]
    s = load(write_ply(tmp_path / "coloured.ply", colours))
    linear = srgb_to_linear(colours)
    np.testing.assert_allclose(s.albedo, [linear[[0, 2, 1]].mean(0), linear[[0, 3, 2]].mean(0)], rtol=1e-6)
    np.testing.assert_array_equal(s.emission, 0)
    np.testing.assert_allclose(s.face_normals, [[0, 1, 0]] * 2, atol=1e-9)
    assert s.groups == ("coloured",)


def test_ply_face_colours_become_albedo(tmp_path):
    s = load(write_ply(tmp_path / "faces.ply", None, [(255, 0, 0), (0, 0, 255)]))
    np.testing.assert_allclose(s.albedo, [[0.999, 0, 0], [0, 0, 0.999]])


def test_ply_without_colours_gets_the_default_albedo(tmp_path):
    from viewer.scene.loaders import DEFAULT_ALBEDO

    s = load(write_ply(tmp_path / "plain.ply", None))
    np.testing.assert_allclose(s.albedo, [DEFAULT_ALBEDO] * 2)


# ---- groups ----------------------------------------------------------------------------------------------

def test_groups_sharing_vertices_move_independently(tmp_path):
    """Two materials share an edge in the file; moving one group must not drag the other."""
    (tmp_path / "two.mtl").write_text("newmtl a\nKd 0.2 0.2 0.2\nnewmtl b\nKd 0.8 0.8 0.8\n")
    (tmp_path / "two.obj").write_text("mtllib two.mtl\nv 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\n"
                                      "usemtl a\nf 1 3 2\nusemtl b\nf 1 4 3\n")
    s = load(tmp_path / "two.obj")
    lift = np.eye(4)
    lift[1, 3] = 1.0
    moved = s.transformed_group("a", lift)
    np.testing.assert_allclose(moved.triangles[group_faces(s, "a")][..., 1], 1.0)
    np.testing.assert_allclose(moved.triangles[group_faces(s, "b")], s.triangles[group_faces(s, "b")])
    np.testing.assert_allclose(s.group_albedo("a"), 0.2)


# ---- sidecar JSON ----------------------------------------------------------------------------------------

TRIANGLE_OBJ = "v 0 0 0\nv 0 0 1\nv 1 0 0\nf 1 2 3\n"


def test_sidecar_gives_sun_and_camera(tmp_path):
    (tmp_path / "lit.obj").write_text(TRIANGLE_OBJ)
    (tmp_path / "lit.json").write_text(json.dumps({
        "sun": {"direction": [0, 2, 0], "irradiance": [3, 2, 1]},
        "camera": {"origin": [1, 2, 3], "fov": 50}}))
    s = load(tmp_path / "lit.obj")
    np.testing.assert_allclose(s.sun.direction, (0, 1, 0))
    np.testing.assert_allclose(s.sun.irradiance, (3, 2, 1))
    assert s.camera.origin == (1, 2, 3) and s.camera.fov == 50 and s.camera.target == (0, 0, 0)


def test_sun_argument_overrides_the_sidecar(tmp_path):
    (tmp_path / "lit.obj").write_text(TRIANGLE_OBJ)
    (tmp_path / "lit.json").write_text(json.dumps({"sun": {"direction": [0, 1, 0], "irradiance": [3, 2, 1]}}))
    s = load(tmp_path / "lit.obj", sun=DirectionalLight((1, 0, 0), (1, 1, 1)))
    np.testing.assert_allclose(s.sun.direction, (1, 0, 0))


# ---- bad input: always one line, always SceneError ----------------------------------------------------

GARBAGE = bytes(np.random.default_rng(7).integers(0, 256, 2048, dtype=np.uint8))
BAD_OBJ = {
    "index-out-of-range": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
    "index-zero": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
    "relative-index-out-of-range": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n",
    "nan-vertex": "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    "infinite-vertex": "v inf 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    "no-faces": "v 0 0 0\nv 1 0 0\nv 0 1 0\n",
    "two-corner-face": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n",
    "letters-in-vertex": "v 0 zero 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    "short-vertex": "v 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    "letters-in-face": "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n",
}
BAD_SIDECARS = {
    "not-json": "{sun: up}",
    "a-list": "[1, 2, 3]",
    "sun-without-irradiance": '{"sun": {"direction": [0, 1, 0]}}',
    "zero-sun-direction": '{"sun": {"direction": [0, 0, 0], "irradiance": [1, 1, 1]}}',
    "negative-sun": '{"sun": {"direction": [0, 1, 0], "irradiance": [-1, 1, 1]}}',
    "fov-not-a-number": '{"camera": {"fov": "wide"}}',
    "camera-a-number": '{"camera": 5}',
}


def assert_scene_error(path, **kwargs) -> str:
    with pytest.raises(SceneError) as info:
        load(path, **kwargs)
    message = str(info.value)
    assert message and "\n" not in message and len(message) < 400, message
    return message


def test_missing_file(tmp_path):
    assert "no such file" in assert_scene_error(tmp_path / "missing.obj")


def test_unknown_builtin_lists_the_builtins():
    assert "cornell" in assert_scene_error("no-such-scene")


def test_directory(tmp_path):
    (tmp_path / "folder.obj").mkdir()
    assert "directory" in assert_scene_error(tmp_path / "folder.obj")
    assert_scene_error(tmp_path)


def test_unsupported_suffix(tmp_path):
    (tmp_path / "box.stl").write_bytes(b"solid box\nendsolid box\n")
    assert "unsupported" in assert_scene_error(tmp_path / "box.stl")


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".glb", ".gltf"])
def test_empty_file(tmp_path, suffix):
    (tmp_path / f"empty{suffix}").write_bytes(b"")
    assert_scene_error(tmp_path / f"empty{suffix}")


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".glb", ".gltf"])
def test_garbage_bytes(tmp_path, suffix):
    (tmp_path / f"garbage{suffix}").write_bytes(GARBAGE)
    assert_scene_error(tmp_path / f"garbage{suffix}")


@pytest.mark.parametrize("case", BAD_OBJ)
def test_malformed_obj(tmp_path, case):
    """A clear one-line error, naming the line where the file is wrong."""
    (tmp_path / f"{case}.obj").write_text(BAD_OBJ[case])
    message = assert_scene_error(tmp_path / f"{case}.obj")
    if case != "no-faces":
        assert f"{case}.obj:" in message and any(f".obj:{n}:" in message for n in range(1, 6)), message


def test_malformed_mtl_colour(tmp_path):
    (tmp_path / "bad.mtl").write_text("newmtl m\nKd red green blue\n")
    (tmp_path / "bad.obj").write_text("mtllib bad.mtl\nusemtl m\n" + TRIANGLE_OBJ)
    assert_scene_error(tmp_path / "bad.obj")


@pytest.mark.parametrize("case", BAD_SIDECARS)
def test_malformed_sidecar(tmp_path, case):
    (tmp_path / "scene.obj").write_text(TRIANGLE_OBJ)
    (tmp_path / "scene.json").write_text(BAD_SIDECARS[case])
    assert "scene.json" in assert_scene_error(tmp_path / "scene.obj")


def test_ply_face_index_out_of_range(tmp_path):
    path = write_ply(tmp_path / "bad.ply", None)
    path.write_text(path.read_text().replace("3 0 3 2", "3 0 7 2"))
    assert_scene_error(path)


def test_ply_point_cloud(tmp_path):
    path = tmp_path / "points.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                    "property float z\nend_header\n0 0 0\n1 1 1\n")
    assert "no triangles" in assert_scene_error(path)


def test_ply_truncated(tmp_path):
    path = write_ply(tmp_path / "short.ply", None)
    path.write_text("\n".join(path.read_text().splitlines()[:-3]) + "\n")
    assert_scene_error(path)


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_gltf_with_a_missing_accessor(tmp_path, suffix):
    path = write_gltf(tmp_path / f"broken{suffix}", GLOW)
    if suffix == ".gltf":
        document = json.loads(path.read_text())
        document["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = 9
        path.write_text(json.dumps(document))
    else:
        path.write_bytes(path.read_bytes()[:40])  # cut inside the JSON chunk
    assert_scene_error(path)


@pytest.mark.parametrize("document", ["[1, 2, 3]", '{"asset": {"version": "2.0"}}', '"text"',
                                      '{"asset": {"version": "2.0"}, "nodes": "x", "extensions": 3}'])
def test_gltf_json_that_is_not_a_scene(tmp_path, document):
    (tmp_path / "odd.gltf").write_text(document)
    assert_scene_error(tmp_path / "odd.gltf")


def test_gltf_malformed_light(tmp_path):
    path = write_gltf(tmp_path / "light.gltf", GLOW)
    document = json.loads(path.read_text())
    document["nodes"][2]["rotation"] = "sideways"
    path.write_text(json.dumps(document))
    assert_scene_error(path)
