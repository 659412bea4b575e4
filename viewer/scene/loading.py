"""Scenes from files and by name: the top of the scene modules.

    viewer.scene        load(source): built-in names, the sidecar JSON, which reader reads a file
    viewer.scene.obj    OBJ + MTL -> Scene      viewer.scene.gltf   glTF, GLB -> Scene      viewer.scene.loaders   PLY -> Scene
    viewer.scene.types  Scene, DirectionalLight, Camera, SceneError: the data type, imports neither

Imports run downwards only. The data type is re-exported here, so `from viewer.scene import Scene,
load` keeps working for every stage after loading.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from viewer.scene import gltf
from viewer.scene import loaders
from viewer.scene import obj
from viewer.scene.files import check_readable, inside
from viewer.resources import SCENES
from viewer.scene.types import MAX_COORDINATE, Camera, DirectionalLight, Scene, SceneError, note

__all__ = ["Camera", "DirectionalLight", "Scene", "SceneError", "ASSETS", "SUPPORTED_SUFFIXES",
           "builtin_names", "load", "read_sidecar", "parse_sun", "unlit_warning", "note"]

ASSETS = SCENES
"""The folder of the built-in scenes (viewer.resources: assets/scenes/ of a checkout, or in the wheel)."""
SUPPORTED_SUFFIXES = (".obj", ".glb", ".gltf", ".ply")
SIDECAR_BYTES = 1 << 20
"""The largest sidecar JSON read (1 MiB): it holds a sun and a camera."""


def builtin_names() -> list[str]:
    return sorted(p.stem for p in ASSETS.glob("*.obj"))


def scene_file(source: str | Path) -> Path:
    """The file behind a scene argument: a built-in name (no suffix, no such file) is
    assets/scenes/<name>.obj."""
    path = Path(source)
    if not path.suffix and not path.exists():
        return ASSETS / f"{source}.obj"
    return path


def load(source: str | Path, sun: DirectionalLight | None = None) -> Scene:
    """Load a built-in scene by name (`cornell`, `paper-train-1` ... `paper-test`) or a file.

    A sidecar `<file>.json` next to the file may give a sun and a camera (see `read_sidecar`); `sun`
    overrides both the sidecar and a glTF `KHR_lights_punctual` directional light.
    """
    path = scene_file(source)
    if path != Path(source) and not path.exists():
        raise SceneError(f"unknown scene {str(source)!r}: not a file and not a built-in "
                         f"({', '.join(builtin_names())})")
    if not path.exists():
        raise SceneError(f"{path}: no such file")
    if path.is_dir():
        raise SceneError(f"{path}: is a directory, not a scene file")
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise SceneError(f"{path}: unsupported format {suffix or '(none)'!r}; "
                         f"use one of {', '.join(SUPPORTED_SUFFIXES)}")
    check_readable(path)   # before opening it: a pipe would block, a huge file would be read whole
    try:
        with open(path, "rb") as fh:
            fh.read(1)
    except OSError as exc:
        raise SceneError(f"{path}: cannot read ({exc.strerror or exc})") from None

    scene = _separate_groups(_read(path))
    for message in sidecar_notes(path):
        note(message)
    side = read_sidecar(path)
    if side.get("sun") is not None:
        scene = scene.with_sun(side["sun"])
    if side.get("camera") is not None:
        scene = replace(scene, camera=side["camera"])
    if sun is not None:
        scene = scene.with_sun(sun)
    return scene


def _read(path: Path) -> Scene:
    """The reader of the file's format (the suffix was checked by `load`)."""
    if path.stat().st_size == 0:
        raise SceneError(f"{path}: empty file")
    suffix = path.suffix.lower()
    if suffix == ".obj":
        return obj.read(path)
    return gltf.read(path) if suffix in (".gltf", ".glb") else loaders.read(path)


def _separate_groups(scene: Scene) -> Scene:
    """Give every group its own copy of the vertices it shares with another group (files share them
    along material borders), so that `transformed_group` moves one group only."""
    n = len(scene.vertices)
    keys, inverse = np.unique(scene.face_group[:, None] * n + scene.faces, return_inverse=True)
    if len(keys) == len(np.unique(scene.faces)):
        return scene
    return replace(scene, vertices=scene.vertices[keys % n], faces=inverse.reshape(scene.faces.shape))


SIDECAR_KEYS = ("sun", "camera")
SHARED_SIDECAR = "scene.json"
"""The sidecar a folder with a single scene file may give it under this name."""


def sidecar_path(path: Path) -> Path | None:
    """The sidecar JSON of scene file `path`: `<name>.json` (`room.obj` -> `room.json`), else
    `<name>.<suffix>.json` (`room.obj.json`), else `scene.json` when `path` is the only scene file in its
    folder; None when there is none."""
    for candidate in (path.with_suffix(".json"), path.with_name(path.name + ".json")):
        if candidate.is_file() and candidate != path and inside(path.parent, candidate.name):
            return candidate
    shared = path.with_name(SHARED_SIDECAR)
    if shared.is_file() and inside(path.parent, shared.name) and _scene_files(path.parent) == [path.name]:
        return shared
    return None


def _scene_files(folder: Path) -> list[str]:
    try:
        return sorted(p.name for p in folder.iterdir() if p.suffix.lower() in SUPPORTED_SUFFIXES and p.is_file())
    except OSError:
        return []


def sidecar_notes(path: Path) -> list[str]:
    """Why a sidecar beside scene file `path` is not read, or what of it is not used, one line each: a
    `scene.json` in a folder of several scene files, keys other than "sun" and "camera"."""
    found = sidecar_path(path)
    shared = path.with_name(SHARED_SIDECAR)
    linked = [c for c in (path.with_suffix(".json"), path.with_name(path.name + ".json"), shared)
              if c != path and c.is_file() and not inside(path.parent, c.name)]
    if found is None and linked:
        return [f"{linked[0]} is not read: it links to {linked[0].resolve()}, outside the scene's folder "
                f"{path.parent.resolve()} (a scene reads only its own folder)"]
    if found is None and shared.is_file():
        count = len(_scene_files(path.parent))
        return [f"{shared} is not read for {path.name}: its folder holds {count} scene files, and scene.json "
                f"serves a folder of one; name it {path.with_suffix('.json').name} to give {path.name} its sun "
                f"and camera"]
    if found is None:
        return []
    try:
        data = json.loads(found.read_text())
    except (OSError, ValueError, RecursionError):   # read_sidecar says so, as an error
        return []   # read_sidecar says so, as an error
    if not isinstance(data, dict):
        return []
    unused = [key for key in data if key not in SIDECAR_KEYS]
    if not unused:
        return []
    return [f"{found}: {', '.join(repr(k) for k in unused)} not used (a sidecar gives "
            f"{' and '.join(repr(k) for k in SIDECAR_KEYS)})"]


def read_sidecar(path: Path) -> dict:
    """The sidecar of scene file `path` (`sidecar_path`: `room.json`, `room.obj.json`, or `scene.json`
    beside a single scene file), all keys optional:

        {"sun": {"direction": [x, y, z], "irradiance": [r, g, b]},
         "camera": {"origin": [...], "target": [...], "up": [...], "fov": 39.3}}

    `direction` points from the scene towards the sun; the camera's `fov` is vertical, in degrees, and
    the keys it leaves out take the defaults of viewer.scene.Camera.
    """
    candidate = sidecar_path(path)
    if candidate is None:
        return {}
    check_readable(candidate, "sidecar JSON", limit=SIDECAR_BYTES)   # a pipe would block the load
    try:
        data = json.loads(candidate.read_text())
        out = {}
        if data.get("sun"):
            out["sun"] = DirectionalLight(data["sun"]["direction"], data["sun"]["irradiance"])
        if data.get("camera"):
            out["camera"] = _sidecar_camera(data["camera"])
        return out
    except SceneError as exc:  # e.g. a zero sun direction: say which file
        raise SceneError(f"{candidate}: {exc}") from None
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError, OverflowError) as exc:
        raise SceneError(f"{candidate}: malformed sidecar ({type(exc).__name__}: {str(exc)[:160]})") from None


def _sidecar_camera(c: dict) -> Camera:
    """A sidecar's camera, checked: three finite numbers each for origin, target and up, a target apart
    from the origin, an up not along the view, a field of view between 0 and 180 degrees."""
    def point(key):
        value = np.asarray(c.get(key, getattr(Camera, key)), np.float64)   # ValueError/TypeError: malformed
        if value.shape != (3,) or not np.all(np.isfinite(value)) or np.abs(value).max() > MAX_COORDINATE:
            raise SceneError(f"camera {key}: expected three finite numbers")
        return value

    origin, target, up = point("origin"), point("target"), point("up")
    fov = float(c.get("fov", Camera.fov))
    view = target - origin
    if np.linalg.norm(view) < 1e-12 * max(1.0, np.abs(origin).max()):
        raise SceneError("camera: the origin and the target are the same point")
    if np.linalg.norm(np.cross(view / np.linalg.norm(view), up)) < 1e-6 * max(np.linalg.norm(up), 1e-300):
        raise SceneError("camera: up is zero or along the view")
    if not 0.0 < fov < 180.0:
        raise SceneError(f"camera fov {fov}: expected degrees between 0 and 180")
    return Camera(tuple(map(float, origin)), tuple(map(float, target)), tuple(map(float, up)), fov)


def unlit_warning(scene: Scene) -> str | None:
    """One line for a scene that nothing lights (no emitting material and no sun), naming the fixes; None
    for a lit scene. Its pictures are black but for the albedo and normals views."""
    if scene.has_emitters:
        return None
    return (f"{scene.name} has no emitter and no sun, so its light is black: give a material an emission "
            f"(Ke in an OBJ's .mtl, emissiveFactor in glTF) or add a sun (\"sun\" in a sidecar {scene.name}.json, "
            f"or --sun dx,dy,dz,r,g,b on capture, sample and bake)")


def parse_sun(text: str) -> DirectionalLight:
    """`dx,dy,dz,r,g,b` (direction towards the sun, then irradiance) for the command line."""
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        raise SceneError(f"--sun {text!r}: expected six numbers dx,dy,dz,r,g,b") from None
    if len(values) != 6:
        raise SceneError(f"--sun {text!r}: expected six numbers dx,dy,dz,r,g,b")
    return DirectionalLight(values[:3], values[3:])
