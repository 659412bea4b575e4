"""PLY -> Scene through trimesh (OBJ/MTL has its own reader, viewer.scene.obj, and glTF/GLB its own,
viewer.scene.gltf; viewer.scene picks the reader by suffix).

Vertex colours averaged per face, or face colours (sRGB, 8 bit), as the albedo; without colours every
face gets DEFAULT_ALBEDO; no emission. Every parse failure becomes a one-line `SceneError`.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from viewer.scene.types import Scene, SceneError, srgb_to_linear

DEFAULT_ALBEDO = (0.7, 0.7, 0.7)
"""The albedo of a PLY without colours (as an OBJ face without a material): a light grey that bounces
light the way a painted wall does."""


def read(path: Path) -> Scene:
    """A PLY file as one Scene, named and grouped after the file."""
    import trimesh

    try:
        # trimesh casts whatever numbers the file holds (a NaN colour to uint8, say) and numpy warns on
        # the user's terminal; what comes back is checked here and by Scene instead.
        with np.errstate(all="ignore"):
            loaded = trimesh.load_scene(io.BytesIO(path.read_bytes()), file_type="ply", process=False)
    except Exception as exc:  # trimesh raises anything from KeyError to struct.error on bad files
        raise SceneError(f"{path}: cannot parse PLY file ({_one_line(exc)})") from None
    parts = [_part(path, vertices, faces, visual) for vertices, faces, visual in _meshes(path, loaded)]
    if not parts:
        raise SceneError(f"{path}: no triangles found")
    return Scene.concatenate(path.stem, parts)


def _one_line(exc: Exception) -> str:
    text = str(exc).strip().splitlines()
    return (text[0] if text else type(exc).__name__)[:160]


def _meshes(path: Path, loaded):
    """(world vertices, faces counter-clockwise from the front, visual) per triangle mesh."""
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
            raise SceneError(f"{path}: NaN or infinite vertex positions in {geometry_name!r}")
        with np.errstate(over="ignore", invalid="ignore"):  # too large for float64: Scene says so in one line
            vertices = vertices @ transform[:3, :3].T + transform[:3, 3]
        yield vertices, faces, mesh.visual


def _part(path: Path, vertices, faces, visual) -> Scene:
    """One mesh as a one-group Scene named after the file."""
    albedo = _colour_albedo(faces, visual)
    return Scene(path.stem, vertices, faces, albedo, np.zeros(3), np.zeros(len(faces), np.int64), (path.stem,))


def _colour_albedo(faces, visual) -> np.ndarray:
    """Per-face albedo from vertex colours (averaged per face) or face colours, else the default."""
    kind = getattr(visual, "kind", None)
    if kind == "vertex":
        return srgb_to_linear(np.asarray(visual.vertex_colors, np.float64)[:, :3] / 255.0)[faces].mean(axis=1)
    if kind == "face":
        return srgb_to_linear(np.asarray(visual.face_colors, np.float64)[:, :3] / 255.0)
    return np.tile(DEFAULT_ALBEDO, (len(faces), 1))
