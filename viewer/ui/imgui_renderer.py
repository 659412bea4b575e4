"""Dear ImGui draw data -> moderngl, with the texture protocol of imgui >= 1.92.

Since 1.92 imgui owns its textures' pixels and asks the renderer to create, update and destroy GPU
copies of them (`ImTextureData` with a `status` of want_create / want_updates / want_destroy, listed in
`ImDrawData.textures` every frame); a renderer announces that it does so with
`io.backend_flags |= RendererHasTextures`. This replaces the old `fonts.get_tex_data_as_rgba32()`
upload, which no longer exists (moderngl-window 3.1.1's bundled integration still calls it). The
protocol is the one of imgui's `imgui_impl_opengl3.cpp`, `ImGui_ImplOpenGL3_UpdateTexture`.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import imgui_bundle
import moderngl
import numpy as np
from imgui_bundle import imgui

VERTEX_SHADER = """
#version 330 core
uniform mat4 projection;
in vec2 in_position;
in vec2 in_uv;
in vec4 in_color;
out vec2 uv;
out vec4 color;
void main() {
    uv = in_uv;
    color = in_color;
    gl_Position = projection * vec4(in_position, 0.0, 1.0);
}
"""

FRAGMENT_SHADER = """
#version 330 core
uniform sampler2D atlas;
in vec2 uv;
in vec4 color;
out vec4 frag_color;
void main() {
    frag_color = color * texture(atlas, uv);
}
"""

TEXTURE_UNIT = 0


def create_imgui_context(font_size: float) -> None:
    """A new current imgui context: no imgui.ini in the user's folder, and imgui_bundle's DroidSans at
    font_size (imgui's own font where the file is missing)."""
    imgui.create_context()
    imgui.get_io().set_ini_filename(None)
    font = Path(imgui_bundle.__file__).parent / "assets" / "fonts" / "DroidSans.ttf"
    if font.is_file():
        imgui.get_io().fonts.add_font_from_file_ttf(str(font), font_size)


class ImguiRenderer:
    """Draws imgui's draw data into the currently bound framebuffer of `ctx`.

    Textures created for imgui are kept in `textures` by their GL name, which is also the
    `ImTextureID` imgui stores; `register_texture` lets panels show other moderngl textures with
    `imgui.image(texture.glo, ...)`.
    """

    def __init__(self, ctx: moderngl.Context):
        if not imgui.get_current_context():
            raise RuntimeError("ImguiRenderer: create an imgui context first (imgui.create_context())")
        self.ctx = ctx
        self.io = imgui.get_io()
        self.program = ctx.program(vertex_shader=VERTEX_SHADER, fragment_shader=FRAGMENT_SHADER)
        self.program["atlas"].value = TEXTURE_UNIT
        self._vertices = ctx.buffer(reserve=imgui.VERTEX_SIZE * 65536, dynamic=True)
        self._indices = ctx.buffer(reserve=imgui.INDEX_SIZE * 65536, dynamic=True)
        self._array = ctx.vertex_array(
            self.program, [(self._vertices, "2f 2f 4f1", "in_position", "in_uv", "in_color")],
            index_buffer=self._indices, index_element_size=imgui.INDEX_SIZE)
        self.textures: dict[int, moderngl.Texture] = {}
        self._owned: set[int] = set()   # GL names of the textures imgui asked for
        self.io.backend_flags |= imgui.BackendFlags_.renderer_has_textures
        platform = imgui.get_platform_io()
        platform.renderer_texture_max_width = platform.renderer_texture_max_height = ctx.info["GL_MAX_TEXTURE_SIZE"]

    # ---- textures -----------------------------------------------------------------------------------
    def register_texture(self, texture: moderngl.Texture) -> int:
        """Make a moderngl texture drawable by `imgui.image`; returns its ImTextureID."""
        self.textures[texture.glo] = texture
        return texture.glo

    def update_textures(self, textures) -> None:
        """Carry out imgui's requests on its textures (`ImDrawData.textures`)."""
        for texture in textures:
            status = texture.status
            if status == imgui.ImTextureStatus.want_create:
                self._create(texture)
            elif status == imgui.ImTextureStatus.want_updates:
                self._update(texture)
            elif status == imgui.ImTextureStatus.want_destroy and texture.unused_frames > 0:
                self._destroy(texture)

    @staticmethod
    def _pixels(texture: imgui.ImTextureData) -> np.ndarray:
        """The CPU copy as (H, W, 4) uint8 (rgba32 as it is; alpha8 as white with that alpha, which is
        what the fragment shader's `color * texture` needs)."""
        flat = np.asarray(texture.get_pixels_array(), np.uint8)
        if texture.format == imgui.ImTextureFormat.rgba32:
            return flat.reshape(texture.height, texture.width, 4)
        alpha = flat.reshape(texture.height, texture.width, 1)
        return np.concatenate([np.full_like(alpha, 255)] * 3 + [alpha], axis=2)

    def _create(self, texture: imgui.ImTextureData) -> None:
        gl_texture = self.ctx.texture((texture.width, texture.height), 4, self._pixels(texture).tobytes())
        # Bilinear: imgui's baked anti-aliased lines sample between texels.
        gl_texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
        gl_texture.repeat_x = gl_texture.repeat_y = False
        self.textures[gl_texture.glo] = gl_texture
        self._owned.add(gl_texture.glo)
        texture.set_tex_id(gl_texture.glo)
        texture.set_status(imgui.ImTextureStatus.ok)

    def _update(self, texture: imgui.ImTextureData) -> None:
        gl_texture = self.textures.get(texture.tex_id)
        if gl_texture is None or gl_texture.size != (texture.width, texture.height):
            # Resized atlas, or an id that is not ours: make a fresh copy of the whole thing.
            self._forget(texture.tex_id)
            texture.set_tex_id(0)
            self._create(texture)
            return
        pixels = self._pixels(texture)
        for rect in texture.updates:
            block = np.ascontiguousarray(pixels[rect.y:rect.y + rect.h, rect.x:rect.x + rect.w])
            gl_texture.write(block.tobytes(), viewport=(rect.x, rect.y, rect.w, rect.h))
        texture.set_status(imgui.ImTextureStatus.ok)

    def _destroy(self, texture: imgui.ImTextureData) -> None:
        self._forget(texture.tex_id)
        texture.set_tex_id(0)
        texture.set_status(imgui.ImTextureStatus.destroyed)

    def _forget(self, glo: int) -> None:
        if glo in self._owned:
            self._owned.discard(glo)
            self.textures.pop(glo).release()

    # ---- drawing ------------------------------------------------------------------------------------
    def render(self, draw_data: imgui.ImDrawData, framebuffer: moderngl.Framebuffer | None = None) -> None:
        """Upload texture changes, then draw every command list with its clip rectangle."""
        if draw_data.textures is not None:
            self.update_textures(draw_data.textures)
        width, height = draw_data.display_size
        scale_x, scale_y = draw_data.framebuffer_scale
        fb_width, fb_height = int(width * scale_x), int(height * scale_y)
        if fb_width <= 0 or fb_height <= 0 or not draw_data.cmd_lists_count:
            return
        ctx = self.ctx
        framebuffer = framebuffer or ctx.screen
        framebuffer.use()
        ctx.viewport = (0, 0, fb_width, fb_height)
        left, top = draw_data.display_pos
        right, bottom = left + width, top + height
        self.program["projection"].value = (
            2.0 / (right - left), 0.0, 0.0, 0.0,
            0.0, 2.0 / (top - bottom), 0.0, 0.0,
            0.0, 0.0, -1.0, 0.0,
            (right + left) / (left - right), (top + bottom) / (bottom - top), 0.0, 1.0)
        ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        ctx.enable(moderngl.BLEND)
        ctx.blend_equation = moderngl.FUNC_ADD
        ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA,
                          moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        try:
            for commands in draw_data.cmd_lists:
                self._upload(commands)
                for command in commands.cmd_buffer:
                    self._draw(command, (left, top), (scale_x, scale_y), fb_height)
        finally:
            ctx.scissor = None
            ctx.disable(moderngl.BLEND)

    def _upload(self, commands) -> None:
        vertex_bytes = commands.vtx_buffer.size() * imgui.VERTEX_SIZE
        index_bytes = commands.idx_buffer.size() * imgui.INDEX_SIZE
        for buffer, size in ((self._vertices, vertex_bytes), (self._indices, index_bytes)):
            if buffer.size < size:
                buffer.orphan(max(size, 2 * buffer.size))
        # Straight from imgui's memory, no copy through Python lists.
        self._vertices.write((ctypes.c_byte * vertex_bytes).from_address(commands.vtx_buffer.data_address()))
        self._indices.write((ctypes.c_byte * index_bytes).from_address(commands.idx_buffer.data_address()))

    def _draw(self, command, origin, scale, fb_height: int) -> None:
        if command.elem_count == 0:
            return
        x0, y0, x1, y1 = command.clip_rect
        x0, x1 = (x0 - origin[0]) * scale[0], (x1 - origin[0]) * scale[0]
        y0, y1 = (y0 - origin[1]) * scale[1], (y1 - origin[1]) * scale[1]
        if x1 <= x0 or y1 <= y0:
            return
        texture = self.textures.get(command.tex_ref.get_tex_id())
        if texture is None:
            return  # a texture imgui has not asked for yet (or already destroyed): nothing to draw with
        texture.use(location=TEXTURE_UNIT)
        # GL's scissor origin is the bottom-left corner; imgui's clip rectangles are top-left based.
        self.ctx.scissor = (int(x0), int(fb_height - y1), int(x1 - x0), int(y1 - y0))
        # No RendererHasVtxOffset flag: imgui keeps vtx_offset at 0 and splits large lists instead.
        self._array.render(moderngl.TRIANGLES, vertices=command.elem_count, first=command.idx_offset)

    def shutdown(self) -> None:
        """Release every GL object, marking imgui's textures destroyed so a new renderer can recreate them."""
        if imgui.get_current_context():
            for texture in imgui.get_platform_io().textures:
                if texture.tex_id in self._owned:
                    self._destroy(texture)
            self.io.backend_flags &= ~imgui.BackendFlags_.renderer_has_textures
        for glo in list(self._owned):
            self._forget(glo)
        for obj in (self._array, self._vertices, self._indices, self.program):
            obj.release()
