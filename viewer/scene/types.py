"""The Scene data type: triangle meshes with Lambertian materials, area emitters and an optional sun.

`Scene` is the first data type of the pipeline (Scene -> VoxelGrid -> ProbeGrid -> pixels). It is a
flat triangle soup: every face carries its albedo, its emitted radiance and the index of the group
(material or object) it came from, so that a group can be recoloured without reloading the file.

Conventions (docs/ARCHITECTURE.md): the file's own units and axes, y up; an emitter emits from its front
face only, the side from which its vertices run counter-clockwise.

The bottom of the scene modules: the file formats (viewer.scene.obj, viewer.scene.loaders) build Scenes, and
viewer.scene picks the format of a file and loads built-in scenes by name; this module imports neither.
"""

from __future__ import annotations

import copy
import sys
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from viewer.scene.geometry import TriangleGeometry, group_vertices, transform_rows
from viewer.threads import cores_for


MAX_COORDINATE = 1e15
"""Largest vertex coordinate: the renderer and the compute solver work in float32 (up to 3.4e38), and
triangle areas, squares of coordinates, summed over a voxel, must stay finite there."""
MAX_RADIANCE = 1e30
"""Largest emitted radiance (and sun irradiance): the bounces, the probes' SH and the renderer work in
float32 (up to 3.4e38) and multiply it by areas, solid angles and the bounce series' sum; a value finite
in float64 but past this would come out as NaN or infinity in the probes and the picture."""


def _own_colours(values, face_count: int) -> np.ndarray:
    """(F, 3) float64 colours a scene can keep: a read-only array of that shape as it is (another scene's,
    or one an edit made for it), else a copy (a million-triangle scan's two copies took 0.15 s a drag)."""
    array = np.asarray(values, np.float64)
    if array.shape == (face_count, 3) and not array.flags.writeable:
        return array
    return np.broadcast_to(array, (face_count, 3)).copy()


class SceneError(ValueError):
    """A scene file (or scene description) that cannot be used; the message is one readable line."""


def note(message: str) -> None:
    """One line for the user on stderr (`viewer: ...`) about a scene that loads but may not be what they
    meant (nothing lights it, a sidecar left unread, a lamp too dim)."""
    print(f"viewer: {message}", file=sys.stderr, flush=True)


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 decoding of colours in 0..1 (8-bit file colours, textures): albedo is linear."""
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


@dataclass(frozen=True)
class DirectionalLight:
    """A sun: parallel light from one direction."""

    direction: np.ndarray
    """Unit vector (3,) pointing from the scene towards the light."""
    irradiance: np.ndarray
    """RGB irradiance (W/m^2) on a surface facing the light (Mitsuba's `directional` emitter)."""

    def __post_init__(self):
        d = np.asarray(self.direction, np.float64).reshape(3)
        e = np.asarray(self.irradiance, np.float64).reshape(3)
        if not (np.all(np.isfinite(d)) and np.linalg.norm(d) > 1e-9):
            raise SceneError("directional light: direction must be a finite non-zero vector")
        if not np.all(np.isfinite(e)) or np.any(e < 0):
            raise SceneError("directional light: irradiance must be finite and non-negative")
        if np.any(e > MAX_RADIANCE):
            raise SceneError(f"directional light: irradiance beyond {MAX_RADIANCE:.0e} (the GI works in float32)")
        object.__setattr__(self, "direction", d / np.linalg.norm(d))
        object.__setattr__(self, "irradiance", e)


@dataclass(frozen=True)
class Camera:
    """A pinhole camera; `fov` is the vertical field of view in degrees."""

    origin: tuple[float, float, float] = (0.0, 0.0, 3.9)
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov: float = 39.3077


@dataclass(frozen=True)
class Scene(TriangleGeometry):
    """A triangle soup with per-face Lambertian material and emission."""

    name: str
    vertices: np.ndarray
    """(V, 3) float64 positions."""
    faces: np.ndarray
    """(F, 3) int64 vertex indices, counter-clockwise seen from the front."""
    albedo: np.ndarray
    """(F, 3) float64 diffuse reflectance in [0, 1)."""
    emission: np.ndarray
    """(F, 3) float64 emitted radiance (front side only)."""
    face_group: np.ndarray
    """(F,) int64 index into `groups`."""
    groups: tuple[str, ...]
    """Names of the materials / objects, for editing colours by name."""
    sun: DirectionalLight | None = None
    camera: Camera = field(default_factory=Camera)
    cameras: tuple[Camera, ...] = ()
    """The file's own cameras (a glTF's perspective cameras, in its node tree's order); the first is the
    opening view, `camera`, unless a sidecar gives one. Empty: the file has none."""
    uv: np.ndarray | None = None
    """(F, 3, 2) float64 texture coordinates of each face's corners (glTF's: (0, 0) is the image's top-left),
    with the material's texture transform applied; None: no face is textured."""
    textures: tuple = ()
    """Per group, its base-colour texture (viewer.scene.textures.Texture) or None; empty: none. A textured
    face's albedo at a point is `albedo` x texture(uv) / texture.mean: `albedo` stays the face's mean."""

    def __post_init__(self):
        v = np.ascontiguousarray(self.vertices, np.float64)
        f = np.ascontiguousarray(self.faces, np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
            raise SceneError(f"{self.name}: vertices and faces must be (n, 3) arrays")
        if len(f) == 0 or len(v) == 0:
            raise SceneError(f"{self.name}: the scene has no triangles")
        self._check_positions(v)
        if f.min() < 0 or f.max() >= len(v):
            raise SceneError(f"{self.name}: face indices out of range (0..{len(v) - 1})")
        # Voxelizing weighs every triangle by its area: some must be non-zero.
        doubled_area = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
        if not np.any(doubled_area > 0):
            raise SceneError(f"{self.name}: every triangle is degenerate (zero area)")
        group = np.broadcast_to(np.asarray(self.face_group, np.int64), (len(f),)).copy()
        for name, value in (("vertices", v), ("faces", f), ("face_group", group)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "groups", tuple(self.groups) or ("default",))
        self._check_colours(len(f))

    def _check_positions(self, v: np.ndarray) -> None:
        if not np.all(np.isfinite(v)):
            raise SceneError(f"{self.name}: vertex positions contain NaN or infinity")
        if len(v) and np.abs(v).max() > MAX_COORDINATE:
            raise SceneError(f"{self.name}: vertex coordinates beyond +-{MAX_COORDINATE:.0e} (the GPU computes "
                             f"areas in float32)")

    def _error(self, message: str) -> SceneError:
        return SceneError(f"{self.name}: {message}")

    def _check_colours(self, face_count: int, checked: tuple[str, ...] = ()) -> None:
        """Check and keep the albedo and emission, but those `checked` already (another scene's arrays)."""
        fresh = {name: _own_colours(getattr(self, name), face_count)
                 for name in ("albedo", "emission") if name not in checked}
        if not all(np.all(np.isfinite(values)) for values in fresh.values()):
            raise SceneError(f"{self.name}: material colours contain NaN or infinity")
        emission = fresh.get("emission")
        if emission is not None and np.any(emission < 0):
            raise SceneError(f"{self.name}: negative emission")
        if emission is not None and np.any(emission > MAX_RADIANCE):
            raise SceneError(f"{self.name}: emitted radiance beyond {MAX_RADIANCE:.0e} (the GI works in float32)")
        # Albedo 1 never converges (eq. 30 is a geometric series in albedo): keep it just below.
        albedo = fresh.get("albedo")
        if albedo is not None and (albedo.min() < 0.0 or albedo.max() > 0.999):
            fresh["albedo"] = np.clip(albedo, 0.0, 0.999)
        for name, value in fresh.items():
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        self._check_textures(face_count)

    def _recoloured(self, **changes) -> "Scene":
        """A copy with other colours (albedo, emission, textures, sun): the same geometry arrays, and what
        is derived from them (areas, normals, bounds, `geometry_digest`) kept, where `replace` would check
        and derive it again (0.1 s of a colour edit on a 68k-triangle scan). Stages that compare scenes
        see the same triangles by identity."""
        scene = copy.copy(self)
        if "emission" in changes:
            scene.__dict__.pop("emitting", None)
        for name, value in changes.items():
            object.__setattr__(scene, name, value)
        scene._check_colours(len(scene.faces), tuple(n for n in ("albedo", "emission") if n not in changes))
        return scene

    def _check_textures(self, face_count: int) -> None:
        textures = tuple(self.textures)
        if textures and len(textures) != len(self.groups):
            raise SceneError(f"{self.name}: {len(textures)} textures for {len(self.groups)} groups")
        if any(t is not None and not hasattr(t, "pixels") for t in textures):
            raise SceneError(f"{self.name}: a group's texture is not a Texture")
        uv = self.uv
        if uv is not None:
            uv = np.asarray(uv, np.float64)
            uv = uv if uv.shape == (face_count, 3, 2) else uv.reshape(face_count, 3, 2)
            if uv.flags.writeable:   # a caller's array: copied; a scene's own (read-only) is kept by colour edits
                uv = uv.copy()
            if not np.all(np.isfinite(uv)):
                raise SceneError(f"{self.name}: texture coordinates contain NaN or infinity")
            uv.setflags(write=False)
        if uv is None or not any(t is not None for t in textures):
            uv, textures = None, ()
        object.__setattr__(self, "uv", uv)
        object.__setattr__(self, "textures", textures)

    @cached_property
    def emitting(self) -> np.ndarray:
        """(F,) bool, read-only: the faces that emit in some channel (asked by several stages an edit; a
        million-triangle scan's took 30 ms a time). A colour edit of the emission makes it again."""
        e = self.emission
        out = (e[:, 0] > 0) | (e[:, 1] > 0) | (e[:, 2] > 0)
        out.setflags(write=False)
        return out

    @property
    def has_emitters(self) -> bool:
        return bool(self.emitting.any()) or (self.sun is not None and np.any(self.sun.irradiance > 0))

    # ---- edits (return new scenes) ----------------------------------------------------------------
    def group_index(self, group: str) -> int:
        try:
            return self.groups.index(group)
        except ValueError:
            raise SceneError(f"{self.name}: no group named {group!r} (have {', '.join(self.groups)})") from None

    @property
    def textured(self) -> bool:
        """Whether some group shows a texture."""
        return bool(self.textures)

    def texture_of(self, group: int):
        """Group `group`'s texture (by index), or None."""
        return self.textures[group] if self.textures else None

    def with_albedo(self, group: str, rgb) -> "Scene":
        """The group in a new colour. A textured group keeps its pattern around the new colour (the
        texture multiplied by the new colour over the old), unless the texture is black throughout in a
        channel the new colour has: then the texture is dropped and the group shows the plain colour."""
        index = self.group_index(group)
        mask = self.face_group == index
        texture = self.texture_of(index)
        if texture is None and np.all(self.albedo[mask] == np.clip(np.asarray(rgb, np.float64), 0.0, 0.999)):
            return self   # the viewer applies every group's colour again after each edit
        albedo = self.albedo.copy()
        albedo[mask] = np.asarray(rgb, np.float64)
        albedo.setflags(write=False)   # the new scene's own: not copied again
        if texture is not None and np.any((texture.mean <= 0) & (albedo[mask] > 0)):
            textures = list(self.textures)
            textures[index] = None
            return self._recoloured(albedo=albedo, textures=tuple(textures))
        return self._recoloured(albedo=albedo)

    def with_emission(self, group: str, rgb) -> "Scene":
        mask = self.face_group == self.group_index(group)
        if np.all(self.emission[mask] == np.asarray(rgb, np.float64)):
            return self   # the viewer applies the lamp's colour again after each drag
        emission = self.emission.copy()
        emission[mask] = np.asarray(rgb, np.float64)
        emission.setflags(write=False)   # the new scene's own: not copied again
        return self._recoloured(emission=emission)

    def with_sun(self, sun: DirectionalLight | None) -> "Scene":
        return self._recoloured(sun=sun)

    def transformed_group(self, group: str, matrix: np.ndarray) -> "Scene":
        """Move the vertices of one group by a 4x4 affine matrix (faces of a group own their vertices
        after `load`, so no other group moves)."""
        index = self.group_index(group)
        m = np.ascontiguousarray(matrix, np.float64)
        # the group's corners and their new places in compiled passes: np.unique of a million-triangle
        # scan's corners took 0.64 s, and the product and its gathers 40 ms
        idx = group_vertices(self.faces, self.face_group, index, len(self.vertices))
        v = self.vertices.copy()
        with cores_for(len(idx)):
            transform_rows(v, idx, m)
        return self._moved(v, idx, recipe=b"group %d " % index + m.tobytes())

    def largest_group(self) -> str:
        """The group whose faces have the largest total area (a room's biggest wall or floor)."""
        return self.groups[int(np.argmax(np.bincount(self.face_group, self.face_areas, len(self.groups))))]

    def group_albedo(self, group: str) -> np.ndarray:
        mask = self.face_group == self.group_index(group)
        return np.average(self.albedo[mask], axis=0, weights=self.face_areas[mask] + 1e-30)

    @staticmethod
    def concatenate(name: str, parts: list["Scene"], sun: DirectionalLight | None = None,
                    camera: Camera | None = None) -> "Scene":
        """The parts as one scene; groups of the same name merge, unless they show different textures (or
        one shows a texture and the other none): then the later one is named "NAME (2)", "NAME (3)", ..."""
        verts, faces, alb, emi, grp, uvs, names, textures = [], [], [], [], [], [], [], []
        offset = 0
        for p in parts:
            verts.append(p.vertices)
            faces.append(p.faces + offset)
            offset += len(p.vertices)
            alb.append(p.albedo)
            emi.append(p.emission)
            uvs.append(p.uv if p.uv is not None else np.zeros((len(p.faces), 3, 2)))
            lookup = []
            for index, g in enumerate(p.groups):
                texture, label, copy = p.texture_of(index), g, 2
                while label in names and textures[names.index(label)] is not texture:
                    label, copy = f"{g} ({copy})", copy + 1
                if label not in names:
                    names.append(label)
                    textures.append(texture)
                lookup.append(names.index(label))
            grp.append(np.asarray(lookup)[p.face_group])
        return Scene(name, np.concatenate(verts), np.concatenate(faces), np.concatenate(alb),
                     np.concatenate(emi), np.concatenate(grp), tuple(names), sun=sun,
                     camera=camera or parts[0].camera, uv=np.concatenate(uvs), textures=tuple(textures))
