"""The scene layer: the `Scene` data type and everything that makes one.

    types.py     Scene, DirectionalLight, Camera, SceneError: the data type (imports nothing of ours)
    loading.py   load(source): built-in names, the sidecar JSON, which reader reads a file
    obj.py       OBJ + MTL -> Scene
    gltf.py      glTF, GLB -> Scene: the node tree, primitives, materials, cameras, lights
    gltf_data.py a glTF's JSON and binary data: buffers (confined to its folder), accessors, images
    gltf_lights.py  KHR_lights_punctual: the sun, point and spot lights as small emitting spheres
    gltf_textures.py a glTF base-colour texture: its image, sampler wrap modes, texture coordinates
    textures.py  Texture (an image, sRGB or linear, wrap modes) and the albedo at a point of a textured face
    loaders.py   PLY (through trimesh) -> Scene
    meshes.py    built-in meshes (boxes, spheres, ...) for procedural scenes
    camera.py    the camera a scene opens with (its file's own, or one framing it)
    files.py     what a scene may open: regular files of bounded size, companions from its own folder

`from viewer.scene import Scene, load` is the face every later stage uses.
"""

from viewer.scene.loading import (ASSETS, SUPPORTED_SUFFIXES, Camera, DirectionalLight, Scene, SceneError,
                                  builtin_names, load, note, parse_sun, read_sidecar, scene_file,
                                  unlit_warning)

__all__ = ["Camera", "DirectionalLight", "Scene", "SceneError", "ASSETS", "SUPPORTED_SUFFIXES",
           "builtin_names", "load", "read_sidecar", "parse_sun", "scene_file",
           "unlit_warning", "note"]
