"""The file formats trimesh parses -> Scene (OBJ/MTL has its own reader, viewer.scene.obj; viewer.scene picks
the reader by suffix).

- glTF/GLB: trimesh reads the geometry and the node graph; materials and lights come from the glTF JSON
  itself, because trimesh 5.2 rounds baseColorFactor to 8 bits and reads neither
  KHR_materials_emissive_strength nor KHR_lights_punctual. Albedo = baseColorFactor x mean linear colour
  of the base-colour texture x COLOR_0 (linear, as glTF's colours are; averaged per face); emission =
  emissiveFactor x KHR_materials_emissive_strength (a file whose emitters all stay at or under 1 without it
  gets a hint: such a lamp barely lights a room); a directional light becomes the sun (its `intensity` x
  `color` read as irradiance in W/m^2).
- PLY (trimesh): vertex colours averaged per face, or face colours (sRGB, 8 bit), as the albedo; no
  emission.
Every parse failure becomes a one-line `SceneError`.
"""

from __future__ import annotations

import io
import json
import struct
import sys
from pathlib import Path

import numpy as np

from viewer.scene.files import check_readable
from viewer.scene.types import DirectionalLight, Scene, SceneError, note

DEFAULT_ALBEDO = (0.7, 0.7, 0.7)
MATERIAL_TAG = "gi-viewer-material-"
"""Prefix of the name each glTF material gets before trimesh parses the file: the name leads a mesh
back to its material's index in the JSON (names may be missing or repeated)."""
MALFORMED = (TypeError, ValueError, KeyError, IndexError, AttributeError)


def read(path: Path) -> Scene:
    """A glTF, GLB or PLY file (chosen by its suffix) as one Scene."""
    suffix = path.suffix.lower()
    gltf, data = _tagged_gltf(path) if suffix in (".gltf", ".glb") else ({}, path.read_bytes())
    loaded = _trimesh_scene(path, data)
    parts = [_part(path, name, vertices, faces, visual, gltf)
             for name, vertices, faces, visual in _meshes(path, loaded)]
    if not parts:
        raise SceneError(f"{path}: no triangles found")
    scene = Scene.concatenate(path.stem, parts, sun=_gltf_sun(path, gltf))
    if gltf and 0.0 < float(scene.emission.max(initial=0.0)) <= 1.0 and not _uses_emissive_strength(gltf):
        note(f"{path}: its emitters' emissiveFactor is at most 1, which lights a room only dimly; glTF "
             f"raises it with KHR_materials_emissive_strength, e.g. \"extensions\": "
             f"{{\"KHR_materials_emissive_strength\": {{\"emissiveStrength\": 20}}}} on the lamp's material")
    return scene


def _uses_emissive_strength(gltf: dict) -> bool:
    return any(isinstance(m, dict) and "KHR_materials_emissive_strength" in (m.get("extensions") or {})
               for m in gltf.get("materials") or [])


def _one_line(exc: Exception) -> str:
    text = str(exc).strip().splitlines()
    return (text[0] if text else type(exc).__name__)[:160]


def _trimesh_scene(path: Path, data: bytes):
    import trimesh

    suffix = path.suffix.lower()[1:]
    resolver = FolderResolver(path)
    try:
        # trimesh casts whatever numbers the file holds (a NaN colour to uint8, say) and numpy warns on
        # the user's terminal; what comes back is checked here and by Scene instead.
        with np.errstate(all="ignore"):
            loaded = trimesh.load_scene(io.BytesIO(data), file_type=suffix, process=False, resolver=resolver)
    except Exception as exc:  # trimesh raises anything from KeyError to struct.error on bad files
        if resolver.refused:   # a buffer the file may not read: say which
            raise SceneError(resolver.refused[0]) from None
        raise SceneError(f"{path}: cannot parse {suffix.upper()} file ({_one_line(exc)})") from None
    if resolver.refused:   # an image trimesh went on without
        print(f"{resolver.refused[0]}; skipped", file=sys.stderr)
    return loaded


class FolderResolver:
    """What a glTF file may read besides itself (trimesh's resolver): regular files of a bounded size inside
    the file's own folder, by the exact name the file gives. Anything else is refused unopened and noted in
    `refused` (one line each): a buffer's refusal is the load's error, an image's is printed and skipped."""

    def __init__(self, path: Path):
        self.path, self.folder, self.refused = path, path.parent.resolve(), []

    def get(self, name: str) -> bytes:
        try:
            target = (self.folder / str(name).strip()).resolve()
        except (OSError, ValueError, RuntimeError):
            target = None
        if target is None or not target.is_relative_to(self.folder):
            self.refused.append(f"{self.path}: {str(name)[:120]!r} lies outside the scene's folder {self.folder}")
            raise SceneError(self.refused[-1])
        try:
            check_readable(target, "glTF buffer or image")
        except SceneError as exc:
            self.refused.append(str(exc))
            raise
        return target.read_bytes()

    __getitem__ = get

    def namespaced(self, namespace: str) -> "FolderResolver":
        return self

    def keys(self):
        return iter(())


def _meshes(path: Path, loaded):
    """(name, world vertices, faces counter-clockwise from the front, visual) per triangle mesh."""
    import trimesh

    for node in loaded.graph.nodes_geometry:
        transform, geometry_name = loaded.graph[node]
        mesh = loaded.geometry[geometry_name]
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            continue
        vertices, faces = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.min() < 0 or faces.max() >= len(vertices):
            raise SceneError(f"{path}: face indices out of range in {geometry_name!r}")
        if not (np.all(np.isfinite(vertices)) and np.all(np.isfinite(transform))):
            raise SceneError(f"{path}: NaN or infinite vertex positions or node transform in {geometry_name!r}")
        with np.errstate(over="ignore", invalid="ignore"):  # too large for float64: Scene says so in one line
            vertices = vertices @ transform[:3, :3].T + transform[:3, 3]
        if np.linalg.det(transform[:3, :3]) < 0:  # a mirroring node swaps the front (glTF 2.0, 3.7.4)
            faces = faces[:, ::-1]
        yield str(geometry_name), vertices, faces, mesh.visual


def _part(path: Path, name: str, vertices, faces, visual, gltf: dict) -> Scene:
    """One mesh as a one-group Scene."""
    if gltf:
        albedo, emission, name = _gltf_material(path, name, faces, visual, gltf)
    else:  # PLY: one mesh, named after the file
        albedo, emission, name = _colour_albedo(faces, visual, _srgb_to_linear), np.zeros(3), path.stem
    return Scene(name, vertices, faces, albedo, emission, np.zeros(len(faces), np.int64), (name,))


def _colour_albedo(faces, visual, decode) -> np.ndarray:
    """Per-face albedo from vertex colours (averaged per face) or face colours, else the default."""
    kind = getattr(visual, "kind", None)
    if kind == "vertex":
        return decode(np.asarray(visual.vertex_colors, np.float64)[:, :3] / 255.0)[faces].mean(axis=1)
    if kind == "face":
        return decode(np.asarray(visual.face_colors, np.float64)[:, :3] / 255.0)
    return np.tile(DEFAULT_ALBEDO, (len(faces), 1))


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 decoding of 8-bit colours."""
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


# ---- glTF: materials and lights from the JSON --------------------------------------------------------------

def _tagged_gltf(path: Path) -> tuple[dict, bytes]:
    """The file's glTF JSON, and the file's bytes with material i renamed MATERIAL_TAG + i."""
    data = path.read_bytes()
    glb = path.suffix.lower() == ".glb"
    if glb:
        if len(data) < 20 or data[:4] != b"glTF" or data[16:20] != b"JSON":
            raise SceneError(f"{path}: not a binary glTF file (no glTF header and JSON chunk)")
        (length,) = struct.unpack_from("<I", data, 12)
        text, rest = data[20:20 + length], data[20 + length:]
    else:
        text, rest = data, b""
    try:
        gltf = json.loads(text)
    except ValueError as exc:
        raise SceneError(f"{path}: glTF JSON does not parse ({_one_line(exc)})") from None
    materials = gltf.get("materials", []) if isinstance(gltf, dict) else None
    if not isinstance(materials, list) or not all(isinstance(m, dict) for m in materials):
        raise SceneError(f"{path}: not a glTF document (expected a JSON object with a list of materials)")
    tagged = json.dumps(dict(gltf, materials=[dict(m, name=f"{MATERIAL_TAG}{i}")
                                              for i, m in enumerate(materials)])).encode()
    if not glb:
        return gltf, tagged
    tagged += b" " * (-len(tagged) % 4)  # chunks are 4-byte aligned
    body = struct.pack("<I4s", len(tagged), b"JSON") + tagged + rest
    return gltf, struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def _gltf_material(path: Path, name: str, faces, visual, gltf: dict):
    """(albedo, emission, group name) of one glTF mesh."""
    material = getattr(visual, "material", None)
    tag = str(getattr(material, "name", None) or "")
    if not tag.startswith(MATERIAL_TAG):  # no material: COLOR_0 (linear) or the default
        return _colour_albedo(faces, visual, lambda c: c), np.zeros(3), name
    index = int(tag[len(MATERIAL_TAG):])
    try:
        spec = gltf["materials"][index]
        pbr = spec.get("pbrMetallicRoughness") or {}
        albedo = _rgb(pbr.get("baseColorFactor", (1.0, 1.0, 1.0)))
        strength = ((spec.get("extensions") or {}).get("KHR_materials_emissive_strength") or {}).get(
            "emissiveStrength", 1.0)
        emission = _rgb(spec.get("emissiveFactor", (0.0, 0.0, 0.0))) * float(strength)
    except MALFORMED as exc:
        raise SceneError(f"{path}: malformed glTF material {index} ({_one_line(exc)})") from None
    texture = getattr(material, "baseColorTexture", None)
    if texture is not None:
        try:  # trimesh hands over anything the JSON held (a list becomes an array); PIL decodes lazily
            pixels = np.asarray(texture.convert("RGB"), np.float64).reshape(-1, 3) / 255.0
        except Exception as exc:  # PIL raises OSError, SyntaxError, zlib.error, ... on bad image data
            raise SceneError(f"{path}: unreadable base-colour texture in glTF material {index} "
                             f"({_one_line(exc)})") from None
        albedo = albedo * _srgb_to_linear(pixels).mean(axis=0)
    colours = _vertex_colours(path, getattr(visual, "vertex_attributes", None) or {}, faces)
    if colours is not None:   # glTF multiplies the base colour by COLOR_0 (linear): per face, the mean
        albedo = albedo[None, :] * colours[faces].mean(axis=1)
    return albedo, emission, str(spec.get("name") or f"material-{index}")


def _vertex_colours(path: Path, attributes, faces) -> np.ndarray | None:
    """A primitive's COLOR_0 beside its material (trimesh keeps it as the `color` vertex attribute) as
    linear RGB in 0..1 per vertex, or None. Normalized integers are scaled to 0..1 (glTF 2.0, 3.7.2.1)."""
    colours = attributes.get("color") if hasattr(attributes, "get") else None
    if colours is None:
        return None
    colours = np.asarray(colours)
    if colours.ndim != 2 or colours.shape[1] not in (3, 4) or len(colours) <= int(np.max(faces, initial=-1)):
        raise SceneError(f"{path}: COLOR_0 is not one RGB or RGBA colour per vertex")
    rgb = colours[:, :3].astype(np.float64)
    if np.issubdtype(colours.dtype, np.integer):
        rgb /= float(np.iinfo(colours.dtype).max)
    if not np.all(np.isfinite(rgb)):
        raise SceneError(f"{path}: COLOR_0 holds NaN or infinite colours")
    return np.clip(rgb, 0.0, None)


def _rgb(values) -> np.ndarray:
    rgb = np.asarray([float(v) for v in list(values)[:3]], np.float64)
    if rgb.shape != (3,) or not np.all(np.isfinite(rgb)):
        raise ValueError(f"{values!r} is not an RGB colour")
    return rgb


def _node_matrix(node: dict) -> np.ndarray:
    if "matrix" in node:
        return np.asarray(node["matrix"], np.float64).reshape(4, 4).T  # glTF is column-major
    t = np.asarray(node.get("translation", [0, 0, 0]), np.float64).reshape(3)
    x, y, z, w = (float(q) for q in node.get("rotation", [0, 0, 0, 1]))
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    s = np.asarray(node.get("scale", [1, 1, 1]), np.float64).reshape(3)
    m = np.eye(4)
    m[:3, :3] = r * s
    m[:3, 3] = t
    return m


def _gltf_sun(path: Path, gltf: dict) -> DirectionalLight | None:
    """The first KHR_lights_punctual directional light, as the sun."""
    try:
        lights = ((gltf.get("extensions") or {}).get("KHR_lights_punctual") or {}).get("lights") or []
        nodes = gltf.get("nodes") or []
        if not lights:
            return None
        parent = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}
        for i, node in enumerate(nodes):
            ext = (node.get("extensions") or {}).get("KHR_lights_punctual")
            if not ext or lights[ext["light"]].get("type") != "directional":
                continue
            light = lights[ext["light"]]
            world, seen, j = np.eye(4), set(), i
            while j is not None and j not in seen:
                world = _node_matrix(nodes[j]) @ world
                seen.add(j)
                j = parent.get(j)
            # The light shines along its node's local -Z; the sun direction points back towards it.
            towards = world[:3, :3] @ np.array([0.0, 0.0, 1.0])
            irradiance = _rgb(light.get("color", (1, 1, 1))) * float(light.get("intensity", 1))
            return DirectionalLight(towards, irradiance)
    except MALFORMED as exc:
        raise SceneError(f"{path}: malformed KHR_lights_punctual light ({_one_line(exc)})") from None
    except SceneError as exc:  # e.g. a zero direction or a negative colour: say which file
        raise SceneError(f"{path}: {exc}") from None
    return None
