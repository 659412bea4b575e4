"""A Scene as a Mitsuba scene: meshes with per-face albedo, area emitters, the sun.

Apart from the estimators (viewer/reference/mitsuba.py), which load the scene this module describes.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from viewer.scene.geometry import NO_TWIN
from viewer.reference.runtime import aligned, loaded, variant
from viewer.scene import Scene
from viewer.scene.textures import textured_faces

SHEET_GAP = 1e-4
"""How far the two faces of a two-sided sheet are pulled apart for Mitsuba, each towards its front, as a
share of the scene's bounding diagonal (0.35 mm in a 2 m room)."""


def sheets_apart(scene: Scene) -> Scene:
    """`scene` with each two-sided sheet's faces (faces on the same corners wound opposite ways:
    `Scene.twins`) moved SHEET_GAP apart, each along its own normal; the scene itself
    where it has none. Mitsuba meets one of two coincident faces from either side, whichever its
    hierarchy tests first (a sheet white on one side and green on the other showed green to both), where
    the viewer's rays meet the face on their side."""
    twin = scene.twins
    if twin is NO_TWIN:
        return scene
    faces = np.flatnonzero(twin >= 0)
    corners = np.asarray(scene.triangles[faces], np.float64)
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    lo, hi = scene.bounds
    corners += (SHEET_GAP * float(np.linalg.norm(hi - lo)) * normal)[:, None, :]
    vertices = np.concatenate([scene.vertices, corners.reshape(-1, 3)])
    indices = np.array(scene.faces, copy=True)
    indices[faces] = len(scene.vertices) + np.arange(3 * len(faces)).reshape(-1, 3)
    return replace(scene, vertices=vertices, faces=indices)


def to_mitsuba(scene: Scene, max_depth: int = -1) -> dict:
    """The Scene as a Mitsuba scene dictionary (for `mi.load_dict`), without a sensor.

    - Faces that emit nothing form one mesh; the faces of each distinct emitted radiance form one mesh
      with an area emitter (Mitsuba evaluates a textured emitter at primitive 0 when it samples it, so
      per-face emission cannot be a face attribute). Per-face albedo is a face attribute read by a
      `mesh_attribute` texture, so thousands of colours cost nothing.
    - No vertex normals: Mitsuba then uses the face normal cross(v1-v0, v2-v0), our CCW front, and its
      area emitters emit on that side only, as ours do.
    - The BSDF is a two-sided diffuse (Mitsuba's `diffuse` alone is black from behind); emission stays
      one-sided. A face lit from behind thus reflects there in Mitsuba, where our rays take its back for
      the inside of a solid and bring no light (docs/ARCHITECTURE.md, "Sides"): the two agree on closed
      surfaces and two-sided sheets and differ only on a lone face seen from behind.
    - The two faces of a two-sided sheet are pulled a hair apart (`sheets_apart`), so that each side
      shows its own face.
    - A textured group's faces that emit nothing form a mesh of their own, with per-corner texture
      coordinates and a `bitmap` reflectance: the texture (linear) times the group's albedo over the
      texture's mean, its wrap modes, bilinear (the renderer's finest mip level). Mitsuba reads texture
      coordinates as glTF does, (0, 0) at the image's top-left.
    - The sun is a `directional` emitter; Mitsuba's `direction` is where the light travels, -sun.direction.
    - Emitters are sampled in proportion to their power (`sampling_weight`); the sun's power is what
      reaches into the scene's bounds (`_sun_lit_fraction`), not all that crosses its bounding disc.
    """
    mi, _, _ = loaded()
    scene = sheets_apart(scene)
    lo, hi = scene.bounds
    radius = 0.5 * float(np.linalg.norm(hi - lo))
    out: dict = {"type": "scene", "integrator": {"type": "path", "max_depth": int(max_depth)}}
    emitting = np.any(scene.emission > 0, axis=1)
    textured = textured_faces(scene) & ~emitting
    if np.any(~emitting & ~textured):
        out["surfaces"] = _mesh(mi, scene, np.flatnonzero(~emitting & ~textured), "surfaces", emitter=None)
    for group in np.unique(scene.face_group[textured]):
        faces = np.flatnonzero(textured & (scene.face_group == group))
        out[f"textured_{group:04d}"] = _textured_mesh(mi, scene, faces, f"textured_{group:04d}")
    if np.any(emitting):
        values, which = np.unique(scene.emission[emitting], axis=0, return_inverse=True)
        faces = np.flatnonzero(emitting)
        areas = scene.face_areas[faces]
        for k, radiance in enumerate(values):
            chosen = which.reshape(-1) == k
            power = np.pi * float(areas[chosen].sum()) * float(radiance.mean())
            emitter = {"type": "area", "radiance": {"type": "rgb", "value": radiance.tolist()},
                       "sampling_weight": max(power, 1e-12)}
            out[f"emitter_{k:04d}"] = _mesh(mi, scene, faces[chosen], f"emitter_{k:04d}", emitter)
    if scene.sun is not None and np.any(scene.sun.irradiance > 0):
        power = float(scene.sun.irradiance.mean()) * np.pi * radius ** 2  # through the bounding disc
        power *= max(_sun_lit_fraction(mi, scene), 1e-3)
        out["sun"] = {"type": "directional", "direction": (-scene.sun.direction).tolist(),
                      "irradiance": {"type": "rgb", "value": scene.sun.irradiance.tolist()},
                      "sampling_weight": max(power, 1e-12)}
    return out


def _sun_lit_fraction(mi, scene: Scene, count: int = 4096) -> float:
    """Share of points spread over the scene's bounds that the sun reaches. A sun shining through a
    small window lights a few percent of a room: weighted by its whole bounding disc it would take nearly
    every light sample and next-event estimate, and leave the area lights to chance (measured on such a
    room, 8^3 probes at 256 directions: two seeds differ by 21% relative RMS with the disc's weight, 8%
    with this one). Any weight keeps the estimate unbiased; this one only moves samples to the light."""
    if variant().startswith("scalar"):
        return 1.0
    lo, hi = scene.bounds
    points = lo + (hi - lo) * np.random.default_rng(0x5E7).random((count, 3))
    towards = np.broadcast_to(scene.sun.direction, points.shape)
    occluders = mi.load_dict({"type": "scene", "surfaces": _mesh(mi, scene, np.arange(len(scene.faces)),
                                                                 "occluders", None)}, parallel=False)
    ray = mi.Ray3f(mi.Point3f(*(mi.Float(aligned(points[:, a])) for a in range(3))),
                   mi.Vector3f(*(mi.Float(aligned(towards[:, a])) for a in range(3))))
    return float(1.0 - np.mean(np.array(occluders.ray_test(ray), bool)))


def _mesh(mi, scene: Scene, face_ids: np.ndarray, name: str, emitter: dict | None):
    """One Mitsuba mesh holding the given faces (their own vertices only), albedo as a face attribute."""
    used, local = np.unique(scene.faces[face_ids], return_inverse=True)
    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "twosided", "material": {
        "type": "diffuse", "reflectance": {"type": "mesh_attribute", "name": "face_albedo"}}})
    if emitter is not None:
        props["emitter"] = mi.load_dict(emitter)
    mesh = mi.Mesh(name, len(used), len(face_ids), props=props)
    params = mi.traverse(mesh)
    positions, indices = params["vertex_positions"], params["faces"]
    params["vertex_positions"] = type(positions)(scene.vertices[used].astype(np.float32).ravel())
    params["faces"] = type(indices)(local.reshape(-1).astype(np.uint32))
    params.update()
    mesh.add_attribute("face_albedo", 3, scene.albedo[face_ids].astype(np.float32).ravel())
    return mesh


def _textured_mesh(mi, scene: Scene, face_ids: np.ndarray, name: str):
    """One Mitsuba mesh of a textured group's faces, three vertices each (a corner's texture coordinate is
    the face's own), its reflectance the group's texture scaled to the faces' albedo. Faces of one group
    share one albedo unless COLOR_0 varied it: then the area-weighted mean scales the texture."""
    texture = scene.textures[int(scene.face_group[face_ids[0]])]
    albedo = np.average(scene.albedo[face_ids], axis=0, weights=scene.face_areas[face_ids] + 1e-30)
    scale = np.where(texture.mean > 0, albedo / np.where(texture.mean > 0, texture.mean, 1.0), 0.0)
    image = np.minimum(texture.linear() * scale.astype(np.float32), 0.999).astype(np.float32)
    wrap = texture.wrap[0] if texture.wrap[0] == texture.wrap[1] else "repeat"   # Mitsuba: one mode for both
    bitmap = {"type": "bitmap", "data": mi.TensorXf(image), "raw": True, "wrap_mode": wrap,
              "filter_type": "nearest" if texture.nearest else "bilinear"}
    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "twosided", "material": {"type": "diffuse", "reflectance": bitmap}})
    mesh = mi.Mesh(name, 3 * len(face_ids), len(face_ids), props=props, has_vertex_texcoords=True)
    params = mi.traverse(mesh)
    positions, indices, texcoords = params["vertex_positions"], params["faces"], params["vertex_texcoords"]
    params["vertex_positions"] = type(positions)(scene.triangles[face_ids].astype(np.float32).ravel())
    params["faces"] = type(indices)(np.arange(3 * len(face_ids), dtype=np.uint32))
    params["vertex_texcoords"] = type(texcoords)(scene.uv[face_ids].astype(np.float32).ravel())
    params.update()
    return mesh


def load_scene(scene: Scene, max_depth: int = -1, sensor: dict | None = None):
    """The loaded Mitsuba scene, with `sensor` when given (an image render's camera)."""
    mi, _, _ = loaded()
    description = to_mitsuba(scene, max_depth)
    if sensor is not None:
        description["sensor"] = sensor
    # Serial loading keeps object ids, hence Dr.Jit kernels, the same from run to run (cache hits).
    return mi.load_dict(description, parallel=False)
