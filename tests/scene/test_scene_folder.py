"""A scene reads only its own folder, and only regular files: a glTF's buffers and images outside the
.gltf's folder are refused (a buffer: the load's one-line error) or skipped with one line (an image); a
buffer or a sidecar JSON that is a pipe is refused without being opened (it would block the load forever).
And an MTL colour that is not finite says "colour"."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from viewer.scene import DirectionalLight, SceneError, load

ROOT = Path(__file__).resolve().parents[2]
POSITIONS = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0]], np.float32)
INDICES = np.array([0, 1, 2], np.uint32)
BLOB = POSITIONS.tobytes() + INDICES.tobytes()


def gltf(buffer_uri: str, image_uri: str | None = None) -> str:
    document = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1]}}],
        "buffers": [{"uri": buffer_uri, "byteLength": len(BLOB)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 12}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 0, 1]},
                      {"bufferView": 1, "componentType": 5125, "count": 3, "type": "SCALAR"}]}
    if image_uri is not None:
        document["images"] = [{"uri": image_uri}]
        document["textures"] = [{"source": 0}]
        document["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    return json.dumps(document)


@pytest.fixture
def folders(tmp_path):
    inner = tmp_path / "scene"
    inner.mkdir()
    (tmp_path / "outside.bin").write_bytes(BLOB)
    (inner / "mesh.bin").write_bytes(BLOB)
    return tmp_path, inner


def test_a_buffer_in_the_gltf_s_folder_loads(folders):
    _, inner = folders
    (inner / "ok.gltf").write_text(gltf("mesh.bin"))
    assert len(load(inner / "ok.gltf").faces) == 1


@pytest.mark.parametrize("uri", ["../outside.bin", "{root}/outside.bin", "sub/../../outside.bin"])
def test_a_buffer_outside_the_gltf_s_folder_is_refused_in_one_line(folders, uri):
    root, inner = folders
    uri = uri.format(root=root)
    (inner / "out.gltf").write_text(gltf(uri))
    with pytest.raises(SceneError) as refused:
        load(inner / "out.gltf")
    message = str(refused.value)
    assert "outside the scene's folder" in message and "\n" not in message, message


def test_an_image_outside_the_gltf_s_folder_is_skipped_with_one_line(folders, capsys):
    root, inner = folders
    (root / "secret.png").write_bytes(b"\x89PNG not really")
    (inner / "img.gltf").write_text(gltf("mesh.bin", "../secret.png"))
    assert len(load(inner / "img.gltf").faces) == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "'../secret.png'" in err[0] and "skipped" in err[0], err


def test_a_buffer_that_is_a_pipe_is_refused_without_opening_it(folders):
    _, inner = folders
    os.mkfifo(inner / "pipe.bin")
    (inner / "pipe.gltf").write_text(gltf("pipe.bin"))
    command = (f"from viewer.scene import load, SceneError\ntry: load({str(inner / 'pipe.gltf')!r})\n"
               "except SceneError as e: print(e)")
    # the timeout guards against the hang this test is about; what it asserts is the message
    result = subprocess.run([sys.executable, "-c", command], capture_output=True, text=True, timeout=600,
                            env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert "not a regular file" in result.stdout and result.stdout.count("\n") == 1, (result.stdout, result.stderr)


def test_a_sidecar_that_is_a_pipe_is_never_opened(tmp_path):
    (tmp_path / "room.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    os.mkfifo(tmp_path / "room.json")
    command = (f"from viewer.scene import load, SceneError\ntry: print(len(load({str(tmp_path / 'room.obj')!r}).faces))\n"
               "except SceneError as e: print(e)")
    # the timeout guards against the hang this test is about; what it asserts is the outcome: the pipe is
    # not a sidecar (the scene loads) or is refused as not a regular file
    result = subprocess.run([sys.executable, "-c", command], capture_output=True, text=True, timeout=600,
                            env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert result.stdout.strip() == "1" or "not a regular file" in result.stdout, (result.stdout, result.stderr)


def test_a_sidecar_nested_past_the_json_parser_is_one_line(tmp_path):
    (tmp_path / "room.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "room.json").write_text("[" * 100000 + "]" * 100000)
    with pytest.raises(SceneError, match="malformed sidecar") as refused:
        load(tmp_path / "room.obj")
    assert "\n" not in str(refused.value) and len(str(refused.value)) < 400


def test_an_mtl_colour_that_is_not_finite_says_colour(tmp_path):
    (tmp_path / "room.mtl").write_text("newmtl lamp\nKd 0.5 nan 0.5\n")
    (tmp_path / "room.obj").write_text("mtllib room.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl lamp\nf 1 2 3\n")
    with pytest.raises(SceneError, match="NaN or infinite colour"):
        load(tmp_path / "room.obj")
    (tmp_path / "room.obj").write_text("v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(SceneError, match="NaN or infinite coordinate"):
        load(tmp_path / "room.obj")


# ---- an OBJ's material libraries, pipes, sizes, and what its light and sidecar camera may hold ----------------------------------------------------------------------------------

def write_obj(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


LAMP_MTL = "newmtl lamp\nKd 0 0 0\nKe 10 10 10\n"
QUAD_USING_LAMP = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl lamp\nf 1 2 3 4\n"


@pytest.mark.parametrize("name", ["../outside.mtl", "{outside}"])
def test_material_libraries_outside_the_scenes_folder_are_skipped_with_a_line(tmp_path, capsys, name):
    """`mtllib ../outside.mtl` (or an absolute path elsewhere) is not read: its lamp does not light the
    scene, and stderr says what was skipped."""
    (tmp_path / "outside.mtl").write_text(LAMP_MTL)
    folder = tmp_path / "room"
    folder.mkdir()
    name = name.format(outside=tmp_path / "outside.mtl")
    room = load(write_obj(folder / "room.obj", f"mtllib {name}\n{QUAD_USING_LAMP}"))
    assert not room.emission.any()
    assert "skipped" in capsys.readouterr().err


def test_links_that_point_outside_the_scenes_folder_are_not_followed(tmp_path, capsys):
    """A material library and a sidecar that sit beside the scene by name but are symbolic links to files
    elsewhere are not read: the lamp and the sun they hold stay out, and each gets a line saying why."""
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "lamp.mtl").write_text(LAMP_MTL)
    (outside / "sun.json").write_text('{"sun": {"direction": [0, 1, 0], "irradiance": [5, 5, 5]}}')
    folder = tmp_path / "room"
    folder.mkdir()
    (folder / "lamp.mtl").symlink_to(outside / "lamp.mtl")
    (folder / "room.json").symlink_to(outside / "sun.json")
    room = load(write_obj(folder / "room.obj", f"mtllib lamp.mtl\n{QUAD_USING_LAMP}"))
    assert not room.emission.any() and room.sun is None
    err = capsys.readouterr().err
    assert "skipped 'lamp.mtl'" in err and "room.json is not read: it links to" in err
    (folder / "room.json").unlink()                       # the same sidecar as a file of the folder is read
    (folder / "room.json").write_text((outside / "sun.json").read_text())
    assert load(folder / "room.obj").sun is not None


def test_material_libraries_inside_the_scenes_folder_are_read(tmp_path):
    (tmp_path / "materials").mkdir()
    (tmp_path / "materials" / "lamp.mtl").write_text(LAMP_MTL)
    room = load(write_obj(tmp_path / "room.obj", f"mtllib materials/lamp.mtl\n{QUAD_USING_LAMP}"))
    assert room.emission.max() == 10.0


def test_a_pipe_named_as_the_scene_is_refused_without_opening_it(tmp_path):
    """Opening a FIFO would block until something writes to it: it is refused from its stat alone."""
    pipe = tmp_path / "scene.obj"
    os.mkfifo(pipe)
    with pytest.raises(SceneError, match="not a regular file"):
        load(pipe)


def test_a_scene_file_past_the_size_limit_is_refused_before_it_is_read(tmp_path):
    from viewer.scene.files import MAX_FILE_BYTES

    huge = tmp_path / "huge.obj"
    with open(huge, "wb") as fh:   # sparse: no disk used
        fh.truncate(MAX_FILE_BYTES + 1)
    with pytest.raises(SceneError, match="MiB"):
        load(huge)


def test_light_past_float32s_range_is_refused(tmp_path):
    """Ke 1e39 and a sun of 1e39 are finite in float64 but put NaN into the float32 probes and picture."""
    (tmp_path / "hot.mtl").write_text("newmtl lamp\nKe 1e39 1e39 1e39\n")
    with pytest.raises(SceneError, match="emitted radiance beyond"):
        load(write_obj(tmp_path / "hot.obj", f"mtllib hot.mtl\n{QUAD_USING_LAMP}"))
    with pytest.raises(SceneError, match="irradiance beyond"):
        DirectionalLight((0.0, 1.0, 0.0), (1e39, 1e39, 1e39))


@pytest.mark.parametrize("camera, message", [
    ({"origin": [""]}, "malformed"), ({"origin": "abc"}, "camera origin|malformed"),
    ({"origin": [0, 0, 1], "target": [0, 0, 1]}, "same point"), ({"up": [0, 0, 0]}, "up is zero"),
    ({"origin": [0, 0, 1e30]}, "three finite"), ({"fov": 0}, "fov")])
def test_a_sidecar_camera_that_cannot_make_a_picture_is_refused(tmp_path, camera, message):
    """A camera with no numbers, a target on its origin or no usable up gave a black picture or a
    TypeError deep in the renderer; it is one line naming the sidecar."""
    room = write_obj(tmp_path / "room.obj", QUAD_USING_LAMP)
    (tmp_path / "room.json").write_text(json.dumps({"camera": camera}))
    with pytest.raises(SceneError, match=message):
        load(room)
