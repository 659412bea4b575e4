"""Scenes from files and by name: the top of the scene modules.

    viewer.scene        load(source): built-in names, the sidecar JSON, which reader reads a file
    viewer.scene.obj          OBJ + MTL -> Scene          viewer.scene.loaders   glTF, GLB, PLY (trimesh) -> Scene
    viewer.scene.types  Scene, DirectionalLight, Camera, SceneError: the data type, imports neither

Imports run downwards only. The data type is re-exported here, so `from viewer.scene import Scene,
load` keeps working for every stage after loading.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from viewer.scene import loaders
from viewer.scene import obj
from viewer.scene.files import check_readable
from viewer.resources import SCENES
from viewer.scene.types import Camera, DirectionalLight, Scene, SceneError

__all__ = ["Camera", "DirectionalLight", "Scene", "SceneError", "ASSETS", "SUPPORTED_SUFFIXES",
           "builtin_names", "load", "read_sidecar", "parse_sun"]

ASSETS = SCENES
"""The folder of the built-in scenes (viewer.resources: assets/scenes/ of a checkout, or in the wheel)."""
SUPPORTED_SUFFIXES = (".obj", ".glb", ".gltf", ".ply")


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
    return obj.read(path) if path.suffix.lower() == ".obj" else loaders.read(path)


def _separate_groups(scene: Scene) -> Scene:
    """Give every group its own copy of the vertices it shares with another group (files share them
    along material borders), so that `transformed_group` moves one group only."""
    n = len(scene.vertices)
    keys, inverse = np.unique(scene.face_group[:, None] * n + scene.faces, return_inverse=True)
    if len(keys) == len(np.unique(scene.faces)):
        return scene
    return replace(scene, vertices=scene.vertices[keys % n], faces=inverse.reshape(scene.faces.shape))


def read_sidecar(path: Path) -> dict:
    """`scene.obj` -> `scene.json` (or `scene.obj.json`), all keys optional:

        {"sun": {"direction": [x, y, z], "irradiance": [r, g, b]},
         "camera": {"origin": [...], "target": [...], "up": [...], "fov": 39.3}}

    `direction` points from the scene towards the sun.
    """
    for candidate in (path.with_suffix(".json"), path.with_name(path.name + ".json")):
        if candidate.exists() and candidate != path:
            break
    else:
        return {}
    try:
        data = json.loads(candidate.read_text())
        out = {}
        if data.get("sun"):
            out["sun"] = DirectionalLight(data["sun"]["direction"], data["sun"]["irradiance"])
        if data.get("camera"):
            c = data["camera"]
            out["camera"] = Camera(tuple(c.get("origin", Camera.origin)), tuple(c.get("target", Camera.target)),
                                   tuple(c.get("up", Camera.up)), float(c.get("fov", Camera.fov)))
        return out
    except SceneError as exc:  # e.g. a zero sun direction: say which file
        raise SceneError(f"{candidate}: {exc}") from None
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise SceneError(f"{candidate}: malformed sidecar ({exc})") from None


def parse_sun(text: str) -> DirectionalLight:
    """`dx,dy,dz,r,g,b` (direction towards the sun, then irradiance) for the command line."""
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        raise SceneError(f"--sun {text!r}: expected six numbers dx,dy,dz,r,g,b") from None
    if len(values) != 6:
        raise SceneError(f"--sun {text!r}: expected six numbers dx,dy,dz,r,g,b")
    return DirectionalLight(values[:3], values[3:])
