"""Hostile input: generated malformed OBJ, PLY and GLB files. Every one is either refused with a
one-line `SceneError` (the command line then exits 2) or loads into a finite Scene that voxelizes;
never another exception, never a hang. Examples hypothesis found are kept below as regression tests."""

import json
import struct
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from viewer.scene import SceneError, load
from viewer.rays.voxels import voxelize

ROOT = Path(__file__).resolve().parents[1]
HOSTILE = settings(max_examples=100, deadline=None, derandomize=True, database=None,
                   suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def loads_cleanly(files: dict[str, bytes]) -> None:
    """Write `files` into a fresh folder and load the first: SceneError in one line, or a finite Scene
    whose voxels are finite; and no numpy RuntimeWarning on the way (it would reach the user's terminal
    with a stray source line)."""
    with warnings.catch_warnings(record=True) as caught:  # recorded, not raised: raising would change the path
        warnings.simplefilter("always", RuntimeWarning)
        _loads_cleanly(files)
    assert not [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]


def _loads_cleanly(files: dict[str, bytes]) -> None:
    with tempfile.TemporaryDirectory() as folder:
        for name, data in files.items():
            (Path(folder) / name).write_bytes(data)
        try:
            scene = load(Path(folder) / next(iter(files)))
        except SceneError as exc:
            message = str(exc)
            assert message and "\n" not in message and len(message) < 600, message
            return
    for values in (scene.vertices, scene.albedo, scene.emission):
        assert np.isfinite(values).all()
    assert np.all(scene.emission >= 0) and np.all((scene.albedo >= 0) & (scene.albedo < 1))
    grid = voxelize(scene, 6)
    assert grid.count > 0
    for values in (grid.position, grid.normal, grid.area, grid.albedo, grid.emission, grid.lights.position):
        assert np.isfinite(values).all()


# ---- OBJ -------------------------------------------------------------------------------------------------

NUMBER_WORDS = st.one_of(
    st.floats(width=64).map(repr), st.integers(-10**30, 10**30).map(str),
    st.sampled_from(["nan", "-inf", "1e999", "1e-320", "0x1p3", "1_0", "", "--1", "1e", ".", "+", "ⅷ", "٣"]),
    st.text(alphabet="0123456789.eE+-xn", max_size=6))
INDEX_WORDS = st.one_of(
    st.integers(-6, 6).map(str), st.integers(-2**70, 2**70).map(str),
    st.tuples(st.integers(-6, 6), st.integers(-6, 6)).map(lambda t: f"{t[0]}/{t[1]}"),
    st.sampled_from(["1//2", "/1", "1/", "1.5", "0x2", "", "a", "-0", "+1"]))
NAMES = st.one_of(st.text(max_size=12), st.sampled_from(["scene.mtl", "x" * 300, "../scene.mtl", "a b.mtl", "."]))
OBJ_LINES = st.one_of(
    st.lists(NUMBER_WORDS, max_size=5).map(lambda w: "v " + " ".join(w)),
    st.lists(INDEX_WORDS, max_size=8).map(lambda w: "f " + " ".join(w)),
    st.integers(3, 1000).map(lambda n: "f " + " ".join(str(1 + i % 3) for i in range(n))),
    NAMES.map(lambda n: "usemtl " + n), NAMES.map(lambda n: "mtllib " + n),
    st.sampled_from(["g group", "o object", "s off", "vt 0 0", "vn 0 1 0", "# comment", "f", "v", "\\", "l 1 2"]),
    st.text(max_size=30),
    st.binary(max_size=30).map(lambda b: b.decode("latin-1")))
VALID_OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3"
MTL_LINES = st.one_of(
    NAMES.map(lambda n: "newmtl " + n),
    st.tuples(st.sampled_from(["Kd", "Ke", "Ka", "Ns"]), st.lists(NUMBER_WORDS, max_size=4)).map(
        lambda t: t[0] + " " + " ".join(t[1])),
    st.text(max_size=20))


@st.composite
def obj_files(draw) -> dict[str, bytes]:
    lines = draw(st.lists(OBJ_LINES, max_size=12))
    if draw(st.booleans()):  # a valid triangle somewhere, so that loading gets past the first error
        lines.insert(draw(st.integers(0, len(lines))), VALID_OBJ)
    if draw(st.booleans()):
        cut = draw(st.integers(0, 40))
        lines.append(draw(st.sampled_from(OBJ_TEMPLATES))[:cut])   # a truncated last line
    separator = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    files = {"scene.obj": separator.join(lines).encode("utf-8", errors="surrogatepass")}
    if draw(st.booleans()):
        mtl = ["newmtl m"] + draw(st.lists(MTL_LINES, max_size=6))
        files["scene.mtl"] = "\n".join(mtl).encode("utf-8", errors="surrogatepass")
        files["scene.obj"] = b"mtllib scene.mtl\nusemtl m\n" + files["scene.obj"]
    return files


OBJ_TEMPLATES = ["v 0.25 -1.5e3 7", "f 1/1/1 2/2/2 3/3/3", "usemtl lamp", "mtllib scene.mtl", VALID_OBJ]


@HOSTILE
@given(obj_files())
def test_generated_obj_is_refused_or_loads_finitely(files):
    loads_cleanly(files)


# ---- PLY -------------------------------------------------------------------------------------------------

def rarely(draw, probability: float = 0.15) -> bool:
    """Most generated files are nearly valid, so that parsing gets far; each corruption is the exception."""
    chances = round(20 * probability)
    return draw(st.sampled_from([False] * (20 - chances) + [True] * chances))  # shrinks towards False


PLY_TYPES = {"float": "f", "double": "d", "uchar": "B", "int": "i", "char": "b", "short": "h", "uint": "I",
             "float32": "f", "int8": "b", "bogus": "f"}
PLY_NUMBERS = st.one_of(st.integers(-2, 6), st.floats(-4, 4, width=32),
                        st.sampled_from([float("nan"), float("inf"), 1e38, -1e-45, 255, 256, 2**31]))


@st.composite
def ply_files(draw) -> dict[str, bytes]:
    fmt = draw(st.sampled_from(["ascii"] * 5 + ["binary_little_endian"] * 3 + ["binary_big_endian", "ascii2"]))
    count = draw(st.integers(3, 6))
    types = [draw(st.sampled_from(["float", "double"])) for _ in "xyz"]
    names = ["x", "y", "z"]
    if draw(st.booleans()):
        colour = draw(st.sampled_from(["uchar"] * 3 + list(PLY_TYPES)))
        types += [colour] * 3
        names += ["red", "green", "blue"]
    list_type = draw(st.sampled_from(["int"] * 6 + ["uint", "uchar", "short", "float", "bogus"]))
    faces = [[draw(st.integers(-1, count) if rarely(draw) else st.integers(0, count - 1)) for _ in range(3)]
             for _ in range(draw(st.integers(1, 4)))]
    if rarely(draw):
        faces.append([0] * draw(st.sampled_from([0, 1, 2, 4, 200])))
    declared = (count + draw(st.sampled_from([-1, 1, 10**9, 2**32])) if rarely(draw) else count,
                len(faces) + draw(st.sampled_from([-1, 1, 10**9])) if rarely(draw) else len(faces))
    header = ["ply", f"format {fmt} 1.0", f"element vertex {declared[0]}",
              *[f"property {t} {n}" for t, n in zip(types, names)], f"element face {declared[1]}",
              f"property list uchar {list_type} vertex_indices"]
    if rarely(draw):
        header.insert(draw(st.integers(1, len(header))), draw(st.text(max_size=20)))
    vertices = [[draw(PLY_NUMBERS) if rarely(draw) else draw(st.floats(-1, 1, width=32)) for _ in types]
                for _ in range(count)]
    if fmt.startswith("ascii"):
        rows = [" ".join(map(str, v)) for v in vertices] + [" ".join(map(str, [len(f), *f])) for f in faces]
        body = "\n".join(rows).encode() + b"\n"
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        body = b""
        for v in vertices:
            for t, value in zip(types, v):
                body += ply_pack(order + PLY_TYPES[t], value)
        for f in faces:
            body += struct.pack("B", len(f) % 256) + b"".join(ply_pack(order + PLY_TYPES[list_type], i) for i in f)
    data = ("\n".join(header) + "\nend_header\n").encode("utf-8", errors="surrogatepass") + body
    if rarely(draw):
        data = data[:draw(st.integers(0, len(data)))]
    if rarely(draw):
        data += draw(st.binary(max_size=40))
    return {"scene.ply": data}


def ply_pack(code: str, value) -> bytes:
    """`value` packed as `code`, or the nearest it can hold (a hostile file may still hold such bytes)."""
    try:
        return struct.pack(code, value)
    except struct.error:
        return struct.pack(code, 0 if code[-1] not in "fd" else float("nan"))


VALID_PLY = (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
             b"element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")


@HOSTILE
@given(ply_files())
@example({"scene.ply": VALID_PLY})
def test_generated_ply_is_refused_or_loads_finitely(files):
    loads_cleanly(files)


# ---- GLB -------------------------------------------------------------------------------------------------

def triangle_gltf() -> tuple[dict, bytes]:
    """One triangle with an index buffer and a material: the document that the GLB cases mutate."""
    positions = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0]], np.float32)
    indices = np.array([0, 1, 2, 0], np.uint16)
    binary = positions.tobytes() + indices.tobytes()
    return {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "translation": [0, 1, 0]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1]}, "emissiveFactor": [1, 1, 1]}],
        "buffers": [{"byteLength": len(binary)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                        {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 0, 1]},
                      {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}],
    }, binary


def glb(document: dict | bytes, binary: bytes, magic=b"glTF", version=2, total=None, json_length=None,
        json_type=b"JSON", bin_length=None) -> bytes:
    text = document if isinstance(document, bytes) else json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<I4s", len(text) if json_length is None else json_length, json_type) + text
    if binary is not None:
        chunks += struct.pack("<I4s", len(binary) if bin_length is None else bin_length, b"BIN\0") + binary
    return struct.pack("<4sII", magic, version, 12 + len(chunks) if total is None else total) + chunks


JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.floats() | st.text(max_size=6)
    | st.sampled_from([-1, 0, 1, 2, 3, 4, 2**31, 2**32 + 1, 10**12, 5120, 5121, 5123, 5125, 5126, "VEC3", "SCALAR", "MAT4"])
    | st.integers(-10**6, 10**6),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=5), inner, max_size=3),
    max_leaves=8)
GLTF_PATHS = [
    ("accessors", 0, "count"), ("accessors", 0, "componentType"), ("accessors", 0, "type"),
    ("accessors", 0, "bufferView"), ("accessors", 0, "byteOffset"), ("accessors", 1, "count"),
    ("accessors", 1, "componentType"), ("accessors", 1, "bufferView"), ("accessors", 0, "max"),
    ("bufferViews", 0, "byteLength"), ("bufferViews", 0, "byteOffset"), ("bufferViews", 0, "buffer"),
    ("bufferViews", 0, "byteStride"), ("bufferViews", 1, "byteOffset"), ("buffers", 0, "byteLength"),
    ("buffers", 0, "uri"), ("meshes", 0, "primitives", 0, "indices"), ("meshes", 0, "primitives", 0, "mode"),
    ("meshes", 0, "primitives", 0, "attributes", "POSITION"), ("meshes", 0, "primitives", 0, "material"),
    ("meshes", 0, "primitives"), ("nodes", 0, "matrix"), ("nodes", 0, "translation"), ("nodes", 0, "rotation"),
    ("nodes", 0, "scale"), ("nodes", 0, "mesh"), ("nodes", 0, "children"), ("scene",), ("scenes", 0, "nodes"),
    ("materials", 0, "emissiveFactor"), ("materials", 0, "pbrMetallicRoughness"),
    ("materials", 0, "extensions"), ("materials",), ("extensions",), ("nodes",), ("accessors",), ("images",),
    ("textures",), ("materials", 0, "pbrMetallicRoughness", "baseColorTexture"),
    # what the glTF reader reads beyond plain triangles: sparse accessors, morph targets and their
    # weights, cameras, required extensions
    ("accessors", 0, "sparse"), ("meshes", 0, "primitives", 0, "targets"), ("meshes", 0, "weights"),
    ("nodes", 0, "weights"), ("nodes", 0, "camera"), ("cameras",), ("extensionsRequired",)]


def png(mode: str) -> str:
    import base64
    import io

    from PIL import Image

    out = io.BytesIO()
    Image.new(mode, (2, 2)).save(out, "PNG")
    return "data:image/png;base64," + base64.b64encode(out.getvalue()).decode()


def truncated_png() -> str:
    import base64

    whole = base64.b64decode(png("RGB").split(",", 1)[1])
    return "data:image/png;base64," + base64.b64encode(whole[:45]).decode()   # header and IHDR, no pixels


IMAGE_URIS = st.sampled_from(["RGB", "LA", "P", "1", "I;16"]).map(png) | st.sampled_from(
    ["data:image/png;base64,iVBORw0KGgoAAAAN", "data:image/png;base64,@@", "missing.png", "", "data:,"]) | st.builds(
    truncated_png)


def add_texture(document: dict, binary: bytes, uri: str) -> bytes:
    """A base-colour texture with texture coordinates (appended to the binary buffer)."""
    offset = len(binary) + (-len(binary) % 4)
    binary = binary.ljust(offset, b"\0") + np.array([[0, 0], [0, 1], [1, 0]], np.float32).tobytes()
    document["bufferViews"].append({"buffer": 0, "byteOffset": offset, "byteLength": 24})
    document["accessors"].append({"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC2"})
    document["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] = 2
    document["buffers"][0]["byteLength"] = len(binary)
    document["images"], document["textures"] = [{"uri": uri}], [{"source": 0}]
    document["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    return binary


def set_path(document, path, value):
    target = document
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value


@st.composite
def glb_files(draw) -> dict[str, bytes]:
    document, binary = triangle_gltf()
    if draw(st.booleans()):
        binary = add_texture(document, binary, draw(IMAGE_URIS))
    for path in draw(st.lists(st.sampled_from(GLTF_PATHS), max_size=3)):
        try:
            set_path(document, path, draw(JSON_VALUES))
        except (KeyError, IndexError, TypeError):
            pass  # an earlier mutation removed the parent
    if draw(st.booleans()):
        document["extensions"] = {"KHR_lights_punctual": {"lights": [draw(JSON_VALUES)]}}
        light = {"extensions": {"KHR_lights_punctual": {"light": draw(JSON_VALUES)}}, "rotation": draw(JSON_VALUES)}
        document["nodes"] = (document["nodes"] if isinstance(document["nodes"], list) else []) + [light]
    text = draw(st.binary(max_size=40) | st.text(max_size=40).map(str.encode)) if rarely(draw, 0.1) else None
    if rarely(draw, 0.3):
        binary = draw(st.sampled_from([binary[:draw(st.integers(0, len(binary)))], None, b"\xff" * 7]))
    fields = {}
    for name, values in (("magic", [b"glTf", b"\0\0\0\0"]), ("version", [1, 0]), ("total", [0, 11, 2**32 - 1]),
                         ("json_length", [0, 1, 7, 2**31, 2**32 - 1]), ("json_type", [b"BIN\0", b"json"]),
                         ("bin_length", [0, 1, 2**32 - 1])):
        if rarely(draw, 0.05):
            fields[name] = draw(st.sampled_from(values))
    data = glb(text if text is not None else document, binary, **fields)
    if rarely(draw, 0.1):
        data = data[:draw(st.integers(0, len(data)))]
    return {"scene.glb": data}


@HOSTILE
@given(glb_files())
@example({"scene.glb": glb(*triangle_gltf())})
def test_generated_glb_is_refused_or_loads_finitely(files):
    loads_cleanly(files)


# ---- the command line: exit 2 and one line -----------------------------------------------------------

def test_the_command_line_refuses_hostile_files_in_one_line(tmp_path):
    np.save(tmp_path / "points.npy", np.zeros((1, 3), np.float32))
    cases = {"truncated.glb": glb(*triangle_gltf())[:50], "bad-index.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
             "short.ply": VALID_PLY[:-8]}
    runs = []
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        runs.append(subprocess.Popen(
            [sys.executable, "-m", "viewer", "sample", str(tmp_path / name), "--points", str(tmp_path / "points.npy"),
             "--out", str(tmp_path / "out.npy"), "--voxels", "4", "--probes", "2"],
            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
    for name, process in zip(cases, runs):
        _, stderr = process.communicate(timeout=120)
        assert process.returncode == 2, (name, stderr)
        assert stderr.count("\n") == 1 and stderr.startswith("error:") and name in stderr, stderr


# ---- what hypothesis found ---------------------------------------------------------------------------

FOUND = {
    # os.stat raised ENAMETOOLONG from Path.is_file while looking for the material library
    "mtllib-name-too-long": {"scene.obj": b"mtllib " + b"x" * 300 + b"\n" + VALID_OBJ.encode()},
    # every face degenerate (a repeated vertex): voxelize found no area to keep and crashed
    "degenerate-faces": {"scene.obj": b"usemtl \nv 0.0 0.0 0.0\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3"},
    # found while fixing the one above: areas that overflow (or underflow) to inf or 0
    "huge-coordinates": {"scene.obj": b"v 0 0 0\nv 1e200 0 0\nv 0 1e200 0\nf 1 2 3\n" + VALID_OBJ.encode()},
    "tiny-coordinates": {"scene.obj": b"v 0 0 0\nv 1e-200 0 0\nv 0 1e-200 0\nf 1 2 3\n"},
    "collinear": {"scene.obj": b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n"},
    # the node transform multiplied an infinite coordinate by zero: "invalid value encountered in matmul"
    "ply-infinite-vertex": {"scene.ply": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                            b"property float y\nproperty float z\nelement face 1\n"
                            b"property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\ninf 1 0\n3 0 1 2\n"},
    # beyond float32 once squared: the compute solver's voxel areas overflowed ("overflow in cast")
    "beyond-float32": {"scene.obj": b"v 0 0 0\nv 3e38 0 0\nv 0 3e38 0\nf 1 2 3\n"},
}


def textured_glb(uri: str, texture_info) -> dict[str, bytes]:
    document, binary = triangle_gltf()
    binary = add_texture(document, binary, uri)
    document["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = texture_info
    return {"scene.glb": glb(document, binary)}


# trimesh passes a baseColorTexture that is not a textureInfo object through as it is (a list becomes a
# numpy array), and loaders called .convert on it
FOUND["texture-info-a-list"] = textured_glb(png("RGB"), [0, 1])
FOUND["texture-info-a-string"] = textured_glb(png("RGB"), "x")
# found while fixing it: PIL opens a PNG lazily, and decoding the missing pixels raised OSError
FOUND["truncated-png"] = textured_glb(truncated_png(), {"index": 0})


@pytest.mark.parametrize("case", FOUND)
def test_what_hypothesis_found(case):
    loads_cleanly(FOUND[case])
