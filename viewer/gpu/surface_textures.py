"""The scene's base-colour textures on the GPU, and the surface pass drawn one group at a time where the
scene has them.

Each textured group's image is one mipmapped 2D texture (sRGB images as SRGB8, so the texture unit decodes
to linear before it filters, as GL does for sRGB formats; linear images as RGB32F), filtered trilinearly.
A scene with textures is drawn in one draw per run of a textured group's faces (the draw order keeps a
group's faces together, viewer/gpu/mesh.py), binding the group's texture, and one draw per run of groups
without one, by the shader variant that samples nothing (on llvmpipe a trilinear sRGB fetch costs about
as much per pixel as the rest of the albedo view); a scene without textures is one draw of that variant. Textures are kept while
the same Texture objects come back (a colour edit), so an edit uploads nothing.
"""

from __future__ import annotations

import moderngl
import numpy as np

from viewer.gpu.mesh import TriangleBuffer, group_runs
from viewer.scene import Scene

BASE_COLOUR_UNIT = 16
"""The texture unit of the base-colour texture (above the lightmaps' and the probes', viewer/gpu/lightmaps.py)."""
GL_SRGB8 = 0x8C41
GL_RGB32F = 0x8815


class SurfaceTextures:
    """The textures of the scene last set, and how its surfaces are drawn with them."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self._uploaded: dict[int, tuple[object, moderngl.Texture]] = {}   # id(Texture) -> (it, GL texture)
        self._groups: list = []
        self._runs: list[tuple[object, int, int]] = []   # (Texture or None, first vertex, vertex count)

    @property
    def active(self) -> bool:
        """Whether the scene shows textures (the surface shader's TEXTURED variant)."""
        return any(texture is not None for texture in self._groups)

    def set_scene(self, scene: Scene) -> None:
        """`scene` in the renderer's draw order (its groups' faces together)."""
        self._groups = list(scene.textures)
        self._runs = []
        for group, first, count in (group_runs(scene) if scene.textured else []):
            texture = self._groups[group]
            if texture is None and self._runs and self._runs[-1][0] is None:   # untextured runs: one draw
                self._runs[-1] = (None, self._runs[-1][1], self._runs[-1][2] + count)
            else:
                self._runs.append((texture, first, count))
        wanted = {id(t) for t in self._groups if t is not None}
        for key in [k for k in self._uploaded if k not in wanted]:
            self._uploaded.pop(key)[1].release()
        for texture in self._groups:
            if texture is not None and id(texture) not in self._uploaded:
                self._uploaded[id(texture)] = (texture, upload(self.ctx, texture))

    def draw(self, mesh: TriangleBuffer, program: moderngl.Program, plain: moderngl.Program) -> None:
        """The mesh's triangles: the textured groups' runs with `program` (the surface shader's TEXTURED
        variant), each with its texture bound, the others with `plain`; all of them with `plain` in a
        scene without textures."""
        if not self.active:
            mesh.render(plain)
            return
        if "base_colour" in program:   # a view that shows no albedo (normals) samples nothing
            program["base_colour"] = BASE_COLOUR_UNIT
        for texture, first, count in self._runs:
            if texture is None:
                mesh.render(plain, first, count)
                continue
            self._uploaded[id(texture)][1].use(location=BASE_COLOUR_UNIT)
            if "mirror_uv" in program:
                program["mirror_uv"] = tuple(float(w == "mirror") for w in texture.wrap)
            mesh.render(program, first, count)

    def release(self) -> None:
        for _, texture in self._uploaded.values():
            texture.release()
        self._uploaded.clear()


def upload(ctx: moderngl.Context, texture) -> moderngl.Texture:
    """A viewer.scene.textures.Texture as a mipmapped GL texture: trilinear (magnified: linear, or nearest
    for a `nearest` texture), REPEAT along an axis whose
    wrap mode repeats, else CLAMP_TO_EDGE (mirrored repeat folds the coordinate in the shader first)."""
    width, height = texture.size
    if texture.srgb:
        gl_texture = ctx.texture((width, height), 3, np.ascontiguousarray(texture.pixels).tobytes(),
                                 alignment=1, internal_format=GL_SRGB8)
    else:
        gl_texture = ctx.texture((width, height), 3, texture.pixels.astype(np.float32).tobytes(), dtype="f4",
                                 internal_format=GL_RGB32F)
    gl_texture.build_mipmaps()
    gl_texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.NEAREST if texture.nearest else moderngl.LINEAR)
    gl_texture.repeat_x = texture.wrap[0] == "repeat"
    gl_texture.repeat_y = texture.wrap[1] == "repeat"
    return gl_texture
