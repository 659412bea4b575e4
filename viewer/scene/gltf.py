"""glTF 2.0 and GLB -> Scene, read from the file's JSON and buffers (viewer.scene.gltf_data) as the glTF 2.0
specification and the Khronos sample models define it.

- Geometry: the default scene's node tree (or every root node when the file names no scene), each node's
  transform (a mirroring node turns the front face, 3.7.4); primitives of mode TRIANGLES, TRIANGLE_STRIP
  and TRIANGLE_FAN as triangles wound as the spec orders their vertices (3.7.2.1); POINTS and LINES* have
  no surface and are skipped with one line; sparse accessors; the default morph target weights (the
  node's `weights`, else the mesh's) applied to POSITION.
- Materials: albedo = baseColorFactor x the mean linear colour of the base-colour texture x COLOR_0
  (linear, averaged per face); a primitive without a material gets glTF's default material, white. The
  base-colour texture itself (sRGB, its sampler's wrap modes) and the texture coordinates it names
  (TEXCOORD_n, moved by KHR_texture_transform) go into the Scene for the renderer, the voxels and Mitsuba
  (viewer.scene.textures).
  Emission = emissiveFactor x KHR_materials_emissive_strength (a file whose emitters all stay at or
  under 1 without it gets a hint: such a lamp barely lights a room).
- Lights (KHR_lights_punctual, viewer.scene.gltf_lights): the first directional light is the sun; a
  point or spot light is a small emitting sphere of the same radiant intensity, a spot's inside a black
  shade whose opening gives it its cone.
- Cameras: every perspective camera in the node tree, in the tree's order; the first is the scene's
  opening view (a sidecar camera overrides it).
- `extensionsRequired`: an extension the viewer does not read is refused in one line naming it.
Every failure is a one-line `SceneError`.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from viewer.scene.gltf_data import MALFORMED, GltfData, integer, one_line, rgb
from viewer.scene.gltf_lights import punctual_lights, shade_group
from viewer.scene.gltf_textures import face_uv, read_texture
from viewer.scene.types import Camera, Scene, SceneError, note

DRACO = "KHR_draco_mesh_compression"
SUPPORTED_EXTENSIONS = {
    "KHR_lights_punctual": "lights",
    "KHR_materials_emissive_strength": "emission above 1",
    "KHR_mesh_quantization": "integer positions: every component type is read, normalized or not",
    "KHR_texture_transform": "the base-colour texture's coordinates move, rotate and scale",
}
"""The extensions a file may require, and what the viewer makes of each."""
TRIANGLE_MODES = {4: "TRIANGLES", 5: "TRIANGLE_STRIP", 6: "TRIANGLE_FAN"}
WIRE_MODES = {0: "POINTS", 1: "LINES", 2: "LINE_LOOP", 3: "LINE_STRIP"}
DEFAULT_ALBEDO = (1.0, 1.0, 1.0)
"""glTF's default material (a primitive without `material`): baseColorFactor (1, 1, 1), no emission."""


def read(path: Path) -> Scene:
    """A .gltf or .glb file as one Scene."""
    data = GltfData(path)
    try:
        _check_extensions(path, data.document)
        scene, dim = _Builder(path, data).scene()
    except SceneError:   # already one line that names the file (SceneError is a ValueError)
        raise
    except MALFORMED as exc:
        raise SceneError(f"{path}: malformed glTF ({one_line(exc)})") from None
    for line in data.refused:
        print(f"{line}; skipped", file=sys.stderr)
    if dim:   # the materials' emission, not the lamps'
        note(f"{path}: its emitters' emissiveFactor is at most 1, which lights a room only dimly; glTF "
             f"raises it with KHR_materials_emissive_strength, e.g. \"extensions\": "
             f"{{\"KHR_materials_emissive_strength\": {{\"emissiveStrength\": 20}}}} on the lamp's material")
    return scene


def _check_extensions(path: Path, document: dict) -> None:
    required = document.get("extensionsRequired", [])
    if not isinstance(required, list):
        raise SceneError(f"{path}: glTF extensionsRequired is not a list")
    for name in required:
        if name == DRACO:
            raise SceneError(f"{path}: its meshes are Draco-compressed ({DRACO}), which the viewer does not "
                             f"decode; export the file without Draco compression")
        if name not in SUPPORTED_EXTENSIONS:
            raise SceneError(f"{path}: requires the glTF extension {str(name)[:80]!r}, which the viewer does "
                             f"not read (it reads {', '.join(sorted(SUPPORTED_EXTENSIONS))})")


class _Builder:
    """Walks the node tree once, gathering triangles, cameras and lights."""

    def __init__(self, path: Path, data: GltfData):
        self.path, self.data = path, data
        self.vertices, self.faces, self.albedo, self.emission, self.group = [], [], [], [], []
        self.uv: list[np.ndarray] = []
        self.groups: list[str] = []
        self.textures: dict[str, object] = {}
        self.materials: dict[int, tuple] = {}
        self.decoded: dict[int, object] = {}   # glTF texture index -> Texture or None
        self.cameras, self.lights, self.wires, self.offset = [], [], [], 0

    def scene(self) -> tuple[Scene, bool]:
        """The Scene, and whether its emitting materials are dim (at most 1, without emissive strength)."""
        for node, world in self._walk():
            if node.get("mesh") is not None:
                self._mesh(node, world)
            if node.get("camera") is not None:
                self.cameras.append((node["camera"], world))
            light = (node.get("extensions") or {}).get("KHR_lights_punctual")
            if light is not None:
                self.lights.append((light.get("light"), world))
        if self.wires:
            note(f"{self.path}: skipped {len(self.wires)} primitive(s) of points or lines "
                 f"({', '.join(sorted(set(self.wires)))}): only surfaces take part in the light")
        if not self.faces:
            raise SceneError(f"{self.path}: no triangles found")
        vertices = np.concatenate(self.vertices)
        with np.errstate(over="ignore", invalid="ignore"):   # Scene refuses non-finite vertices below
            lo, hi = vertices.min(axis=0), vertices.max(axis=0)
            size = float(np.linalg.norm(hi - lo)) if np.all(np.isfinite(hi - lo)) else 1.0
        sun, lamps = punctual_lights(self.path, self.data.document, self.lights, size or 1.0)
        for lamp in lamps:
            self._add(lamp.vertices, lamp.faces, np.zeros((len(lamp.faces), 3)), lamp.radiance, lamp.name)
            if lamp.shade is not None:   # black, and a group of its own: a lamp's colour edit leaves it dark
                vertices, faces = lamp.shade
                self._add(vertices, faces, np.zeros((len(faces), 3)), np.zeros(3), shade_group(lamp.name))
        textures = tuple(self.textures.get(g) for g in self.groups)
        cameras = tuple(c for c in (self._camera(i, world, 0.5 * (lo + hi)) for i, world in self.cameras)
                        if c is not None)
        scene = Scene(self.path.stem, np.concatenate(self.vertices), np.concatenate(self.faces),
                      np.concatenate(self.albedo), np.concatenate(self.emission), np.concatenate(self.group),
                      tuple(self.groups), sun=sun, uv=np.concatenate(self.uv), textures=textures,
                      **({"camera": cameras[0], "cameras": cameras} if cameras else {}))
        glow = max((float(m[1].max()) for m in self.materials.values()), default=0.0)
        return scene, 0.0 < glow <= 1.0 and not any(m[3] for m in self.materials.values())

    # ---- the node tree ------------------------------------------------------------------------------------
    def _walk(self):
        """(node, world matrix) depth first from the default scene's roots (glTF 2.0, 3.5.2: `scene`, else
        scenes[0]; a file without scenes: every node that is no node's child)."""
        document, nodes = self.data.document, self.data.list("nodes")
        if document.get("scene") is not None:
            roots = self.data.item("scenes", document["scene"]).get("nodes", [])
        elif self.data.list("scenes"):
            roots = self.data.item("scenes", 0).get("nodes", [])
        else:
            children = {c for n in nodes if isinstance(n, dict) for c in (n.get("children") or [])
                        if isinstance(c, int)}
            roots = [i for i in range(len(nodes)) if i not in children]
        if not isinstance(roots, list):
            raise SceneError(f"{self.path}: a glTF scene's nodes are not a list")
        seen, stack = set(), [(root, np.eye(4)) for root in reversed(roots)]
        while stack:
            index, parent = stack.pop()
            node = self.data.item("nodes", index)
            if index in seen:
                raise SceneError(f"{self.path}: glTF node {index} appears twice in the node tree")
            seen.add(index)
            world = parent @ node_matrix(node)
            yield node, world
            children = node.get("children", [])
            if not isinstance(children, list):
                raise SceneError(f"{self.path}: glTF node {index}'s children are not a list")
            stack.extend((child, world) for child in reversed(children))

    # ---- meshes -------------------------------------------------------------------------------------------
    def _mesh(self, node: dict, world: np.ndarray) -> None:
        index = node["mesh"]
        mesh = self.data.item("meshes", index)
        primitives = mesh.get("primitives")
        if not isinstance(primitives, list):
            raise SceneError(f"{self.path}: glTF mesh {index} has no list of primitives")
        weights = node.get("weights", mesh.get("weights")) or []
        if not np.all(np.isfinite(world)):
            raise SceneError(f"{self.path}: NaN or infinite node transform on mesh {index}")
        name = str(mesh.get("name") or f"mesh-{index}")
        for primitive in primitives:
            mode = primitive.get("mode", 4)
            if mode in WIRE_MODES and not isinstance(mode, bool):
                self.wires.append(WIRE_MODES[mode])
                continue
            if mode not in TRIANGLE_MODES or isinstance(mode, bool):
                raise SceneError(f"{self.path}: glTF mesh {index} has a primitive of mode {str(mode)[:20]!r}, "
                                 f"not a glTF mode (0-6)")
            self._primitive(primitive, mode, [float(w) for w in weights], world, name)

    def _primitive(self, primitive: dict, mode: int, weights: list[float], world: np.ndarray, name: str) -> None:
        attributes = primitive["attributes"]
        if DRACO in (primitive.get("extensions") or {}) and self.data.item(
                "accessors", attributes["POSITION"]).get("bufferView") is None:
            raise SceneError(f"{self.path}: its meshes are Draco-compressed ({DRACO}), which the viewer does "
                             f"not decode; export the file without Draco compression")
        positions = self.data.accessor(attributes["POSITION"], {"VEC3"}).astype(np.float64)
        targets = primitive.get("targets") or []
        for weight, target in zip(weights, targets):   # glTF 2.0, 3.7.2.2: p = p0 + sum w_i * d_i
            if weight != 0.0 and target.get("POSITION") is not None:
                delta = self.data.accessor(target["POSITION"], {"VEC3"})
                if len(delta) != len(positions):
                    raise SceneError(f"{self.path}: a morph target's POSITION has {len(delta)} elements, its "
                                     f"primitive {len(positions)}")
                positions = positions + weight * delta
        if primitive.get("indices") is not None:
            indices = self.data.accessor(primitive["indices"], {"SCALAR"})[:, 0]
            if not np.issubdtype(indices.dtype, np.integer):
                raise SceneError(f"{self.path}: primitive indices must be unsigned integers")
        else:
            indices = np.arange(len(positions))
        faces = triangles(mode, indices.astype(np.int64))
        if len(faces) == 0:
            return
        if faces.max() >= len(positions):
            raise SceneError(f"{self.path}: face indices out of range (0..{len(positions) - 1}) in {name!r}")
        with np.errstate(over="ignore", invalid="ignore"):  # too large for float64: Scene says so in one line
            vertices = positions @ world[:3, :3].T + world[:3, 3]
        if np.linalg.det(world[:3, :3]) < 0:  # a mirroring node turns the front face (glTF 2.0, 3.7.4)
            faces = faces[:, ::-1]
        albedo, emission, group, texture = self._material(primitive.get("material"), name)
        colours = self._vertex_colours(attributes, len(positions))
        face_albedo = np.tile(albedo, (len(faces), 1))
        if colours is not None:   # glTF multiplies the base colour by COLOR_0 (linear): per face, the mean
            face_albedo = face_albedo * colours[faces].mean(axis=1)
        uv = None
        if texture is not None:   # without the coordinates it names, the texture shows its mean colour
            uv = face_uv(self.data, attributes, texture[0], faces, len(positions))
        self._add(vertices, faces, face_albedo, emission, group, uv, texture[1] if uv is not None else None)

    def _add(self, vertices: np.ndarray, faces: np.ndarray, albedo: np.ndarray, emission: np.ndarray,
             group: str, uv: np.ndarray | None = None, texture=None) -> None:
        """Triangles into the scene: per-face albedo (F, 3), one emitted radiance (3,) for all, a group, and
        the texture they show with their coordinates (F, 3, 2), or None. A group shows one texture (or
        none): faces of a same-named group that show another go to a group "NAME (2)", "NAME (3)", ..."""
        name, copy = group, 2
        while group in self.textures and self.textures[group] is not texture:
            group, copy = f"{name} ({copy})", copy + 1
        self.textures[group] = texture
        self.uv.append(uv if uv is not None else np.zeros((len(faces), 3, 2)))
        if group not in self.groups:
            self.groups.append(group)
        self.vertices.append(vertices)
        self.faces.append(faces + self.offset)
        self.offset += len(vertices)
        self.albedo.append(albedo)
        self.emission.append(np.tile(emission, (len(faces), 1)))
        self.group.append(np.full(len(faces), self.groups.index(group), np.int64))

    def _vertex_colours(self, attributes: dict, count: int) -> np.ndarray | None:
        """COLOR_0 as linear RGB per vertex (float, or normalized unsigned bytes or shorts: glTF 2.0, 3.7.2.1)."""
        if attributes.get("COLOR_0") is None:
            return None
        colours = self.data.accessor(attributes["COLOR_0"], {"VEC3", "VEC4"})
        if len(colours) != count:
            raise SceneError(f"{self.path}: COLOR_0 is not one RGB or RGBA colour per vertex")
        rgb = np.asarray(colours[:, :3], np.float64)
        if not np.all(np.isfinite(rgb)):
            raise SceneError(f"{self.path}: COLOR_0 holds NaN or infinite colours")
        return np.clip(rgb, 0.0, None)

    # ---- materials ----------------------------------------------------------------------------------------
    def _material(self, index, mesh_name: str) -> tuple[np.ndarray, np.ndarray, str, tuple | None]:
        """(albedo, emission, group, (textureInfo, Texture) or None) of material `index`; glTF's default
        material for None, grouped under the mesh's name."""
        if index is None:
            return np.asarray(DEFAULT_ALBEDO), np.zeros(3), mesh_name, None
        index = integer(index, f"{self.path}: material index")
        if index not in self.materials:
            self.materials[index] = self._read_material(index)
        material = self.materials[index]
        return material[0], material[1], material[2], material[4]

    def _read_material(self, index: int) -> tuple:
        spec = self.data.item("materials", index)
        pbr = spec.get("pbrMetallicRoughness") or {}
        try:
            albedo = rgb(pbr.get("baseColorFactor", (1.0, 1.0, 1.0)))
            extension = (spec.get("extensions") or {}).get("KHR_materials_emissive_strength")
            strength = float((extension or {}).get("emissiveStrength", 1.0))
            emission = rgb(spec.get("emissiveFactor", (0.0, 0.0, 0.0))) * strength
        except MALFORMED as exc:   # rgb's ValueError: no SceneError is raised in this block
            raise SceneError(f"{self.path}: malformed glTF material {index} ({one_line(exc)})") from None
        info, texture = pbr.get("baseColorTexture"), None
        if info is not None:
            texture = self._texture(info, index)
            if texture is not None:
                albedo = albedo * texture.mean
        name = str(spec.get("name") or f"material-{index}")
        return albedo, emission, name, extension is not None, (info, texture) if texture is not None else None

    def _texture(self, info: dict, material: int):
        """The base-colour texture `info` names (decoded once per glTF texture), or None when it has no image
        the viewer may read."""
        if not isinstance(info, dict):
            raise SceneError(f"{self.path}: glTF material {material}'s baseColorTexture is not an object")
        index = integer(info.get("index"), f"{self.path}: glTF material {material}'s texture index")
        if index not in self.decoded:
            self.decoded[index] = read_texture(self.path, self.data, index, material)
        return self.decoded[index]

    # ---- cameras and lights -------------------------------------------------------------------------------
    def _camera(self, index, world: np.ndarray, centre: np.ndarray) -> Camera | None:
        """A perspective camera at its node: it looks along local -Z with local +Y up (glTF 2.0, 3.10.1);
        its target is on that axis, as far along it as the scene's centre. None for an orthographic one."""
        spec = self.data.item("cameras", index)
        if spec.get("type") != "perspective":
            return None
        yfov = float(spec["perspective"]["yfov"])
        if not 0.0 < yfov < math.pi:
            raise SceneError(f"{self.path}: glTF camera {index}'s yfov {yfov} is not between 0 and pi radians")
        origin, forward, up = world[:3, 3], world[:3, :3] @ [0.0, 0.0, -1.0], world[:3, :3] @ [0.0, 1.0, 0.0]
        if not (np.all(np.isfinite(world)) and np.linalg.norm(forward) > 0
                and np.linalg.norm(np.cross(forward, up)) > 1e-9 * np.linalg.norm(forward) * np.linalg.norm(up)):
            raise SceneError(f"{self.path}: glTF camera {index}'s node has a degenerate transform")
        forward = forward / np.linalg.norm(forward)
        depth = float(np.dot(centre - origin, forward))
        if depth <= 1e-9 * max(1.0, float(np.abs(origin).max())):
            depth = max(float(np.linalg.norm(centre - origin)), 1.0)
        return Camera(tuple(map(float, origin)), tuple(map(float, origin + depth * forward)),
                      tuple(map(float, up / np.linalg.norm(up))), math.degrees(yfov))


def triangles(mode: int, indices: np.ndarray) -> np.ndarray:
    """(F, 3) faces of a primitive, counter-clockwise from the front, as glTF 2.0 (3.7.2.1) orders them:
    TRIANGLES (v3i, v3i+1, v3i+2); TRIANGLE_STRIP (vi, vi+1+i%2, vi+2-i%2); TRIANGLE_FAN (vi+1, vi+2, v0).
    Strip and fan triangles that repeat a vertex (the joins of stitched strips) have no area and are dropped."""
    if mode == 4:
        return indices[:len(indices) // 3 * 3].reshape(-1, 3)
    i = np.arange(max(len(indices) - 2, 0))
    if mode == 5:
        faces = np.stack([indices[i], indices[i + 1 + i % 2], indices[i + 2 - i % 2]], axis=1)
    else:
        faces = np.stack([indices[i + 1], indices[i + 2], np.full(len(i), indices[0] if len(indices) else 0)], axis=1)
    distinct = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    return faces[distinct].reshape(-1, 3)


def node_matrix(node: dict) -> np.ndarray:
    """A node's local transform: `matrix` (column-major), else translation x rotation x scale (3.5.3)."""
    if "matrix" in node:
        return np.asarray(node["matrix"], np.float64).reshape(4, 4).T
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
