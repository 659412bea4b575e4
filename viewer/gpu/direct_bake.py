"""Baked direct light: diffuse direct irradiance is view-independent, so it is computed once per scene
(and light setting) into a lightmap atlas, and the per-frame surface pass only reads it with one
bilinear fetch (RenderSettings.baked).

Every triangle (A, B, C) gets a tile of (n + 2)^2 texels: the point A + u (B - A) + v (C - A) lies at
tile texel (1 + n u, 1 + n v), n = ceil(longest of |B - A|, |C - A| / texel size); the triangle fills
the lower-left half, and the texels around it (a one-texel border, and those past the diagonal) hold the
irradiance of the nearest point inside, so bilinear filtering never reads another triangle. The bake
evaluates exactly what the per-fragment path does (shaders/direct_light.glsl: the emitter samples with
their shadow atlas, the sun with its shadow map) in one full-screen pass over textures of texel
positions and normals (shaders/direct_bake.glsl), for both sides of every face (surfaces reflect on both
sides: the back sides' lightmap lies right of the front sides' in one texture, so the surface pass
reads either with one fetch). Penumbrae are then linear between texels about a hundredth of the scene's
longest side apart (RenderSettings.lightmap_texel: 0.02 units in the Cornell box).
"""

from __future__ import annotations

import weakref

import moderngl
import numba
import numpy as np

from viewer.gpu.mesh import TriangleBuffer, scene_vertices, write_colours
from viewer.scene.geometry import NO_TWIN
from viewer.scene import Scene, SceneError

ATLAS_WIDTH = 2048
"""Texels along a row of the lightmap atlas (tiles are packed in shelves)."""
MAX_ATLAS_TEXELS = 2048 * 2048
"""The most texels of one side's lightmap (the texture holds both sides, twice this). Each costs about
0.8 kB on the CPU and GPU together (positions, normals, probe weights, the final gather's rays): a room
with 60 plates in it, a 1.96 M texel atlas, peaks at 1.8 GB resident against 0.53 GB for the room
alone, so this bound keeps a scene's lightmap under about 3.5 GB (a room with 150 plates, 4.15 M texels
5% coarser than asked, peaks at 3.3 GB). A scene that would need more gets coarser texels
(`fitted_texel`), and one with more faces than fit at one texel each is refused."""
MIN_TILE = 3
"""Texels along the side of the smallest tile: one texel inside and its border."""


def faces_fit(scene: Scene, max_side: int, max_texels: int | None = None) -> None:
    """Raise SceneError when the scene has more faces than a lightmap holds at any texel spacing: each face
    needs a tile of at least MIN_TILE^2 texels (see `fitted_texel` for `max_side` and `max_texels`)."""
    max_texels = MAX_ATLAS_TEXELS if max_texels is None else max_texels
    faces = int(np.count_nonzero(scene.face_areas > 0))
    width = min(ATLAS_WIDTH, max_side // 2)
    most = min(max_texels // MIN_TILE ** 2, (max_side // MIN_TILE) * (width // MIN_TILE))
    if faces > most:
        raise SceneError(f"{scene.name}: {faces} faces are more than the renderer's lightmap holds ({most}, "
                         f"{MIN_TILE}x{MIN_TILE} texels each at the least)")


def lightmap_holds(scene: Scene, max_side: int) -> bool:
    """Whether a lightmap holds the scene's faces (`faces_fit`); where it does not, the renderer draws the
    scene without lightmaps, its direct and indirect light per fragment."""
    try:
        faces_fit(scene, max_side)
    except SceneError:
        return False
    return True


def fitted_texel(scene: Scene, texel: float, max_side: int, max_texels: int | None = None) -> float:
    """`texel`, or the smallest coarser spacing whose atlas fits: at most `max_texels` texels and a texture
    (twice the atlas's width, for the back sides) of at most `max_side` texels along each side (what the GL
    context allows; `max_texels`: MAX_ATLAS_TEXELS). Raises SceneError for a scene with too many faces
    for any spacing (`faces_fit`)."""
    max_texels = MAX_ATLAS_TEXELS if max_texels is None else max_texels
    faces_fit(scene, max_side, max_texels)
    for _ in range(200):
        _, n, (w, h) = lightmap_layout(scene, texel)
        if 2 * w <= max_side and h <= max_side and w * h <= max_texels:
            return texel
        if np.all(n == 1):      # already one texel a face: coarser texels change nothing
            raise SceneError(f"{scene.name}: {len(n)} faces are more than the renderer's lightmap holds "
                             f"({w}x{h} texels at one texel a face)")
        over = max(2.0 * w / max_side, h / max_side, w * h / max_texels)
        texel *= min(max(1.05, over ** 0.5), 1e6)    # cautious steps: shelves pack less densely than area
    raise SceneError(f"{scene.name}: no lightmap texel spacing fits the scene's faces into the atlas")


def lightmap_layout(scene: Scene, texel: float):
    """Tiles for the scene's non-degenerate faces: (tile origin (F, 2) int, n (F,) int, atlas size).
    Shelf packing, tallest tiles first. The last scene's layout is kept (read-only): `fitted_texel`
    lays the lightmap out for the texel it then makes the lightmap with (10-14 ms on a 68k-triangle scan)."""
    global _last_layout
    if _last_layout is not None and _last_layout[0]() is scene and _last_layout[1] == texel:
        return _last_layout[2]
    layout = _layout(scene, texel)
    for array in layout[:2]:
        array.flags.writeable = False
    _last_layout = (weakref.ref(scene), texel, layout)
    return layout


_last_layout: tuple | None = None   # (weak reference to the scene, texel, layout) of the last call


def _layout(scene: Scene, texel: float):
    keep = scene.face_areas > 0
    corners = scene.triangles[keep].astype(np.float64)
    legs = np.linalg.norm(corners[:, 1:] - corners[:, :1], axis=2).max(axis=1)
    n = np.maximum(np.ceil(legs / texel - 1e-6), 1).astype(int)
    tile = n + 2
    width = max(ATLAS_WIDTH, int(tile.max()))
    origin, height = _shelves(tile, np.argsort(-tile, kind="stable"), width)
    return origin, n, (int(width), int(height))


@numba.njit(cache=True, nogil=True)
def _shelves(tile, order, width):
    """Each tile's lower-left texel, packed in `order` along shelves `width` wide, and the atlas's height
    (compiled: 0.2 s of a 68k-triangle scan's layout as a Python loop)."""
    origin = np.zeros((tile.shape[0], 2), np.int64)
    x = y = shelf = 0
    for f in order:
        if x + tile[f] > width:
            x, y, shelf = 0, y + shelf, 0
        origin[f, 0], origin[f, 1] = x, y
        x += tile[f]
        shelf = max(shelf, tile[f])
    return origin, y + shelf


def lightmap_texels(scene: Scene, origin: np.ndarray, n: np.ndarray, size: tuple[int, int], inset: float = 0.25):
    """(H, W, 4) world positions (w = 1 where a tile covers the texel), (H, W, 4) front normals, (H, W)
    tile (the index among the non-degenerate faces, -1 where none) and (H, W) inside of the atlas texels:
    a tile texel's position is the nearest point of its triangle, `inset` texels inside; `inside` where
    the texel's own point lies in the triangle (the others, half of a tile beyond its triangle's long
    side, are pulled onto its edges: there only for the bilinear filter at the edge)."""
    keep = scene.face_areas > 0
    position = np.zeros((size[1], size[0], 4), np.float32)
    normal = np.zeros((size[1], size[0], 4), np.float32)
    tile = np.full((size[1], size[0]), -1, np.int64)
    inside = np.zeros((size[1], size[0]), np.bool_)
    _fill_tiles(np.ascontiguousarray(scene.triangles[keep], np.float64), np.ascontiguousarray(scene.face_normals[keep]),
                np.ascontiguousarray(origin, np.int64), np.ascontiguousarray(n, np.int64), float(inset), position,
                normal, tile, inside)
    return position, normal, tile, inside


@numba.njit(cache=True, nogil=True)
def _fill_tiles(corners, normals, origin, n, inset, position, normal, tile, inside):
    """Each tile's texels, texel (row r, column c) at u = (c - 0.5) / m, v = (r - 0.5) / m pulled `inset`
    texels inside its triangle (compiled: 79 ms of a new Cornell box's first frame as numpy, where the
    final gather waits for the texels)."""
    for f in range(n.shape[0]):
        m = n[f]
        lo = inset / m
        for r in range(m + 2):
            for c in range(m + 2):
                u, v = max((c - 0.5) / m, lo), max((r - 0.5) / m, lo)
                over = (u + v) / (1.0 - lo)
                inside[origin[f, 1] + r, origin[f, 0] + c] = over <= 1.0 and c > 0 and r > 0
                if over > 1.0:
                    scale = 1.0 / max(over, 1e-9)
                    u, v = u * scale, v * scale
                y, x = origin[f, 1] + r, origin[f, 0] + c
                for a in range(3):
                    position[y, x, a] = (corners[f, 0, a] + u * (corners[f, 1, a] - corners[f, 0, a])
                                         + v * (corners[f, 2, a] - corners[f, 0, a]))
                    normal[y, x, a] = normals[f, a]
                position[y, x, 3] = 1.0
                tile[y, x] = f


def lightmap_vertices(scene: Scene, origin: np.ndarray, n: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(3F, 16) float32: the SceneMesh vertex layout (position, normal, albedo, emission, texture
    coordinate) plus each corner's front-side lightmap coordinate (the back side's is 0.5 further along u)."""
    out = scene_vertices(scene, 16).reshape(-1, 3, 16)
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    texel = origin[:, None, :] + 1.0 + n[:, None, None] * uv[None]          # (F, 3, 2) texel units
    out[..., 14:16] = texel / np.asarray((2 * size[0], size[1]), np.float64)
    return out.reshape(-1, 16)


def same_atlas(a: "BakedDirectLight", b: "BakedDirectLight") -> bool:
    """Whether two lightmaps lay their tiles out alike (the same pixels for the same faces)."""
    return (a.size == b.size and np.array_equal(a.tile_origin, b.tile_origin)
            and np.array_equal(a.tile_n, b.tile_n))


class BakedDirectLight(TriangleBuffer):
    """The scene's triangles with lightmap coordinates (the same vertices as SceneMesh, in the same
    order, so the renderer draws either), and the lightmap (front sides | back sides)."""

    ATTRIBUTES = ("in_position", "in_normal", "in_albedo", "in_emission", "in_uv", "in_lightmap")
    SIZES = {"in_uv": 2, "in_lightmap": 2}

    def __init__(self, ctx: moderngl.Context, scene: Scene, texel: float):
        super().__init__(ctx)
        self.texel = texel
        """Texel spacing in scene units."""
        origin, n, self.size = lightmap_layout(scene, texel)
        self.tile_origin, self.tile_n = origin, n
        """Each face's tile: its lower-left atlas texel (F, 2) and its triangle's texels per side (F,)."""
        vertices = lightmap_vertices(scene, origin, n, self.size)
        self._uv = scene.uv   # the texture coordinates the buffer holds
        self.vertex_count = len(vertices)
        self.buffer = ctx.buffer(np.ascontiguousarray(vertices))   # read in place, not copied
        position, normal, tile, inside = lightmap_texels(scene, origin, n, self.size)
        self.covered = position[..., 3] > 0
        """(H, W) the atlas texels a tile covers."""
        self.texel_points, self.texel_normals = position[self.covered, :3], normal[self.covered, :3]
        """(T, 3) each covered texel's world position and front normal (row-major order)."""
        self.texel_faces = tile[self.covered]
        """(T,) each covered texel's face, as an index into the non-degenerate faces."""
        self.texel_inside = inside[self.covered]
        """(T,) the covered texels whose point lies in their triangle (`lightmap_texels`)."""
        twin = scene.twins
        self.sheets = twin is not NO_TWIN   # the surface pass draws this buffer: each side its own face
        self.texel_back_hidden = (np.zeros(len(self.texel_faces), bool) if twin is NO_TWIN
                                  else (twin >= 0)[scene.face_areas > 0][self.texel_faces])
        """(T,) the covered texels whose back side nothing sees: their face is one side of a two-sided sheet
        (viewer.rays.sides), whose other face is drawn and met there."""
        self._inputs = [ctx.texture(self.size, 4, np.ascontiguousarray(position), dtype="f4"),
                        ctx.texture(self.size, 4, np.ascontiguousarray(normal), dtype="f4")]
        for texture in self._inputs:
            texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.texture = ctx.texture((2 * self.size[0], self.size[1]), 4, dtype="f2")
        self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.texture.repeat_x = self.texture.repeat_y = False
        self.framebuffer = ctx.framebuffer([self.texture])
        self.scale = np.ones(3, np.float32)
        """What the baked irradiance is multiplied by where it is read: a lamp's new colour or intensity in a
        scene lit by its lamps alone scales it (`LightmapUpkeep._ensure_shadows`) instead of a bake."""

    def recolour(self, scene: Scene, rows: np.ndarray | None = None) -> None:
        """Take the colours (albedo, emission) of `scene`, whose triangles are those this was made for;
        the lightmap must be baked again. Only the colours are written (0.1 s less on a 68k-triangle scan):
        of the faces at `rows` (`recoloured_rows`: what the scene's mesh just wrote), or all of them (None);
        where the texture coordinates differ too (a texture dropped), every attribute."""
        if scene.uv is self._uv:   # the same array: `in_draw_order` keeps it across colour edits
            write_colours(self.buffer, scene, rows, 64)
        else:
            self.buffer.write(np.ascontiguousarray(lightmap_vertices(scene, self.tile_origin, self.tile_n, self.size)))
        self._uv = scene.uv

    def bake(self, program: moderngl.Program, first_unit: int) -> None:
        """Fill the lightmaps; `program` is direct_bake.glsl with the light uniforms set. Leaves the
        depth test off (a full-screen pass)."""
        for offset, texture in enumerate(self._inputs):
            texture.use(location=first_unit + offset)
        program["bake_position"] = first_unit
        program["bake_normal"] = first_unit + 1
        self.framebuffer.use()
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        array = self.ctx.vertex_array(program, [])
        array.render(moderngl.TRIANGLES, vertices=3)
        array.release()
        self.scale = np.ones(3, np.float32)

    def use(self, unit: int) -> dict:
        """Bind the lightmap; returns the surface shader's uniforms."""
        self.texture.use(location=unit)
        return dict(lightmap=unit, direct_scale=tuple(float(v) for v in self.scale))

    @property
    def normal_texture(self) -> moderngl.Texture:
        """(W, H) the texels' front normals (what viewer/gpu/indirect_bake.py reads)."""
        return self._inputs[1]

    def release(self) -> None:
        super().release()
        for obj in (self.framebuffer, self.texture, *self._inputs):
            obj.release()
