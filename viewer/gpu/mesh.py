"""GPU geometry: the scene's triangles (flat per-face attributes) and the debug views' instanced shapes."""

from __future__ import annotations

from dataclasses import replace

import moderngl
import numba
import numpy as np

from viewer.rays.moved_faces import changed_rows
from viewer.scene import Scene
from viewer.scene.geometry import NO_TWIN, faces_touching
from viewer.threads import cores_for

SCENE_ATTRIBUTES = ("in_position", "in_normal", "in_albedo", "in_emission", "in_uv")


class TriangleBuffer:
    """A non-indexed triangle list in one interleaved float buffer, bound per program: a program gets a
    vertex array with the attributes it reads, the others skipped. Subclasses set `buffer`,
    `vertex_count`, and may change `ATTRIBUTES` and `SIZES` (floats per attribute, 3 unless listed)."""

    ATTRIBUTES: tuple[str, ...] = SCENE_ATTRIBUTES
    SIZES: dict[str, int] = {"in_uv": 2}

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self._arrays: dict[int, moderngl.VertexArray] = {}

    def vertex_array(self, program: moderngl.Program) -> moderngl.VertexArray:
        """A vertex array binding the attributes this program reads (the others are skipped)."""
        key = program.glo
        if key not in self._arrays:
            size = lambda name: self.SIZES.get(name, 3)
            layout = " ".join(f"{size(n)}f" if n in program else f"{4 * size(n)}x" for n in self.ATTRIBUTES)
            names = [name for name in self.ATTRIBUTES if name in program]
            self._arrays[key] = self.ctx.vertex_array(program, [(self.buffer, layout, *names)])
        return self._arrays[key]

    sheets = False
    """Whether the triangles hold two-sided sheets (faces on the same corners wound opposite ways,
    viewer.rays.sides): `render` then draws the faces that face the camera before those seen from behind,
    pushed back a hair, so that each side of a sheet shows its own face (drawn together, the two faces'
    equal depths took turns along the sheet)."""

    def render(self, program: moderngl.Program, first: int = 0, count: int | None = None) -> None:
        """Draw the triangles, or `count` vertices from vertex `first` (one group's, see `group_runs`)."""
        count = self.vertex_count - first if count is None else count
        array = self.vertex_array(program)
        if not self.sheets:
            array.render(moderngl.TRIANGLES, vertices=count, first=first)
            return
        ctx = self.ctx
        ctx.enable(moderngl.CULL_FACE)
        ctx.cull_face = "back"
        array.render(moderngl.TRIANGLES, vertices=count, first=first)
        ctx.cull_face, ctx.polygon_offset = "front", (1.0, 1.0)
        array.render(moderngl.TRIANGLES, vertices=count, first=first)
        ctx.cull_face, ctx.polygon_offset = "back", (0.0, 0.0)
        ctx.disable(moderngl.CULL_FACE)

    def forget_programs(self) -> None:
        """Drop the vertex arrays (after shaders were reloaded: they point at the old programs)."""
        for array in self._arrays.values():
            array.release()
        self._arrays.clear()

    def release(self) -> None:
        self.forget_programs()
        self.buffer.release()


def in_draw_order(scene: Scene, last: tuple[Scene, Scene, np.ndarray] | None = None
                  ) -> tuple[Scene, Scene, np.ndarray]:
    """(scene, the scene with its faces reordered, the order): groups of small total area first. A room's
    walls, floor and ceiling (its largest groups) lie behind what stands in it, so drawing them last lets
    the depth test reject their hidden fragments before they are shaded (llvmpipe tests depth early), which
    on the Cornell box costs less than a depth pre-pass (about 40% less for the surface pass at 1280x720).
    Each group's faces come together (groups of the same area by index), so a textured group is one draw.
    `last`, this function's answer for an earlier scene of the same faces: the reordered scene is a copy
    of its reordered one, which keeps its derived geometry. A colour edit (the same vertices) puts the new
    colours in the same order (0.1 s less on a 68k-triangle scan); a drag (some vertices moved, the
    groups ranked by area as before) gives the copy the new places too (`Scene._moved`: 0.27 s less on a
    million-triangle scan)."""
    if last is not None and scene.faces is last[0].faces and scene.face_group is last[0].face_group:
        before, reordered, order = last
        if (scene.vertices is not before.vertices and scene.vertices.shape == before.vertices.shape
                and np.array_equal(_group_rank(scene), _group_rank(before))):
            moved = np.flatnonzero(changed_rows((scene.vertices, before.vertices)))
            reordered = reordered._moved(scene.vertices, moved)
        if scene.vertices is reordered.vertices:
            uv = reordered.uv if scene.uv is before.uv else scene.uv[order] if scene.uv is not None else None
            colours = {name: _in_order(getattr(scene, name), getattr(before, name), getattr(reordered, name), order)
                       for name in ("albedo", "emission")}
            reordered = reordered._recoloured(**{n: c for n, c in colours.items() if c is not getattr(reordered, n)},
                                              uv=uv, textures=scene.textures, sun=scene.sun)
            return scene, reordered, order
    area = np.bincount(scene.face_group, weights=scene.face_areas, minlength=len(scene.groups))
    order = np.lexsort((scene.face_group, area[scene.face_group]))
    uv = scene.uv[order] if scene.uv is not None else None
    return scene, replace(scene, faces=scene.faces[order], albedo=scene.albedo[order],
                          emission=scene.emission[order], face_group=scene.face_group[order], uv=uv), order


def _in_order(colours: np.ndarray, before: np.ndarray, kept: np.ndarray, order: np.ndarray) -> np.ndarray:
    """`colours` (F, 3) in draw `order`, read-only: `kept` (`before` in that order) where they are equal."""
    if colours is before or (colours.shape == before.shape and not changed_rows((colours, before)).any()):
        return kept
    out = colours[order]
    out.setflags(write=False)
    return out


def _group_rank(scene: Scene) -> np.ndarray:
    """The groups in `in_draw_order`'s order (by total area, then by index): the faces' order follows."""
    area = np.bincount(scene.face_group, weights=scene.face_areas, minlength=len(scene.groups))
    return np.lexsort((np.arange(len(area)), area))


def group_runs(scene: Scene) -> list[tuple[int, int, int]]:
    """(group, first vertex, vertex count) of each run of faces of one group among the drawn
    (non-degenerate) faces, in order: what one draw of a textured group covers."""
    group = scene.face_group[scene.face_areas > 0]
    starts = np.flatnonzero(np.diff(group, prepend=-1) != 0)
    ends = np.append(starts[1:], len(group))
    return [(int(group[a]), 3 * int(a), 3 * int(b - a)) for a, b in zip(starts, ends)]


def vertex_albedo(scene: Scene, faces=slice(None)) -> np.ndarray:
    """(F, 3) what the surface shader multiplies the texture's colour by: a textured face's albedo over
    its texture's mean colour (the shader's product is then the albedo at the fragment), else the albedo.
    Of the `faces` chosen (a mask or indices) alone where given."""
    albedo = scene.albedo[faces].copy()
    for index, texture in enumerate(scene.textures):
        if texture is not None:
            mean = texture.mean
            chosen = scene.face_group[faces] == index
            albedo[chosen] = np.where(mean > 0, albedo[chosen] / np.where(mean > 0, mean, 1.0), albedo[chosen])
    return albedo


def scene_vertices(scene: Scene, columns: int = 14, faces: np.ndarray | None = None) -> np.ndarray:
    """(3F, columns) float32 over the faces with an area, three vertices a face: position, the face's
    normal, vertex albedo and emission, texture coordinate (14 columns: SceneMesh's layout; the rest left
    for the caller). Of the `faces` given (indices, each with an area) alone where given. Written in one
    compiled pass on every core into the float32 array: numpy's column by column took a million-triangle
    scan's dragged bunny 0.34 s (made in float64 and converted, a 68k-triangle scan's took 33 ms)."""
    chosen = np.flatnonzero(scene.face_areas > 0) if faces is None else np.asarray(faces, np.int64)
    out = np.empty((len(chosen), 3, columns), np.float32)
    uv = scene.uv if scene.uv is not None else np.zeros((0, 3, 2))
    with cores_for(len(chosen)):
        _write_vertices(scene.triangles, scene.face_normals, vertex_albedo(scene, chosen), scene.emission, uv,
                        chosen, out)
    return out.reshape(-1, columns)


@numba.njit(cache=True, nogil=True, parallel=True)
def _write_vertices(triangles, normals, albedo, emission, uv, chosen, out):
    """out[i, corner] = the corner of face chosen[i], its normal, `albedo[i]`, its emission, its texture
    coordinate (0 without `uv`), as float32."""
    for i in numba.prange(chosen.shape[0]):
        f = chosen[i]
        for corner in range(3):
            row = out[i, corner]
            for k in range(3):
                row[k] = triangles[f, corner, k]
                row[3 + k] = normals[f, k]
                row[6 + k] = albedo[i, k]
                row[9 + k] = emission[f, k]
            for k in range(2):
                row[12 + k] = uv[f, corner, k] if uv.shape[0] else 0.0


def same_triangles(a: Scene, b: Scene) -> bool:
    """Whether two scenes have the same triangles in the same order (their colours may differ)."""
    return same_faces(a, b) and (a.vertices is b.vertices or (a.vertices.shape == b.vertices.shape
                                                               and np.array_equal(a.vertices, b.vertices)))


def same_faces(a: Scene, b: Scene) -> bool:
    """Whether two scenes have the same faces (vertex indices) in the same order, wherever their vertices are."""
    return a.faces is b.faces or (a.faces.shape == b.faces.shape and np.array_equal(a.faces, b.faces))


def same_textures(a: Scene, b: Scene) -> bool:
    """Whether two scenes show the same texture objects group by group."""
    return len(a.textures) == len(b.textures) and all(x is y for x, y in zip(a.textures, b.textures))


def face_colours(scene: Scene, faces: np.ndarray) -> np.ndarray:
    """(K, 6) float32: the albedo (`vertex_albedo`) and emission of the `faces` (indices), the attributes
    after position and normal in both vertex layouts (SceneMesh's and the lightmap's), which a colour edit
    writes alone (`write_colours`)."""
    return np.concatenate([vertex_albedo(scene, faces), scene.emission[faces]], axis=1).astype(np.float32)


def recoloured_rows(scene: Scene, previous: Scene) -> np.ndarray:
    """The drawn faces (by their place among the faces with an area, as the vertex buffers hold them) whose
    colours differ from `previous`'s, a scene of the same triangles: found in one compiled comparison of
    the two scenes' colours (comparing every face's colours as written took a million-triangle scan 62 ms
    a lamp's colour edit); all of them where the textures differ (their means divide the albedo)."""
    drawn = scene.face_areas > 0
    if not same_textures(scene, previous):
        return np.arange(int(np.count_nonzero(drawn)))
    changed = np.flatnonzero(changed_rows((scene.albedo, previous.albedo), (scene.emission, previous.emission))
                             & drawn)
    return changed if drawn.all() else np.cumsum(drawn)[changed] - 1


COLOUR_WRITES = 64
"""Past this many runs of consecutive faces to recolour, one write covers them all, first to last."""


def write_colours(buffer: moderngl.Buffer, scene: Scene, rows: np.ndarray | None, stride: int) -> None:
    """Write the colours (`face_colours`) of `scene`'s drawn faces at `rows` (`recoloured_rows`; None: all)
    into a vertex buffer of `stride` bytes a vertex (position and normal first), three vertices a face:
    each run of consecutive faces in one write (a lamp's colour or a wall's is one run of a few faces,
    where all of a 68k-triangle scan's took 6 ms a buffer)."""
    drawn = np.flatnonzero(scene.face_areas > 0)
    rows = np.arange(len(drawn)) if rows is None else np.asarray(rows, np.int64)
    if len(rows) == 0:
        return
    breaks = np.flatnonzero(np.diff(rows) != 1) + 1
    if len(breaks) >= COLOUR_WRITES:
        rows, breaks = np.arange(rows[0], rows[-1] + 1), np.zeros(0, np.int64)
    colours = face_colours(scene, drawn[rows])
    for run in np.split(np.arange(len(rows)), breaks):
        vertices = np.repeat(colours[run], 3, axis=0)
        buffer.write_chunks(vertices.tobytes(), 24 + 3 * int(rows[run[0]]) * stride, stride, len(vertices))


class SceneMesh(TriangleBuffer):
    """The scene as a non-indexed triangle list: every vertex carries its face's normal, albedo and
    emission (flat shading, one material per face) and its texture coordinate. Degenerate faces are
    dropped (no normal)."""

    def __init__(self, ctx: moderngl.Context, scene: Scene):
        super().__init__(ctx)
        self.sheets = scene.twins is not NO_TWIN   # a drag keeps it
        vertices = self._vertices(scene)
        self.vertex_count = len(vertices)
        self.buffer = ctx.buffer(np.ascontiguousarray(vertices))   # read in place, not copied
        self.recoloured: np.ndarray | None = None
        """The rows the last colour edit wrote (`recoloured_rows`), for the lightmap's buffer to write too;
        None where all the vertices were written."""

    @staticmethod
    def _vertices(scene: Scene) -> np.ndarray:
        return scene_vertices(scene)

    @staticmethod
    def remade(old: "SceneMesh | None", ctx: moderngl.Context, scene: Scene, previous: Scene | None) -> "SceneMesh":
        """The mesh of `scene`: `old` (made for `previous`) with the new colours written into its buffer
        where the triangles are the same (a colour edit: its vertex arrays kept; only the colours where the
        texture coordinates are the same too), or the faces that moved or changed colour where the faces
        are the same (a drag: `write_moved`), else a new one (`old` released)."""
        if old is not None and previous is not None and same_triangles(scene, previous):
            if scene.uv is previous.uv:   # the same array: `in_draw_order` keeps it across colour edits
                old.recoloured = recoloured_rows(scene, previous)
                write_colours(old.buffer, scene, old.recoloured, 56)
            else:
                old.buffer.write(np.ascontiguousarray(SceneMesh._vertices(scene)))
                old.recoloured = None
            return old
        if old is not None and previous is not None and old.write_moved(scene, previous):
            return old
        if old is not None:
            old.release()
        return SceneMesh(ctx, scene)

    def write_moved(self, scene: Scene, previous: Scene) -> bool:
        """Write the vertices of the faces that moved or changed colour from `previous` (whose vertices
        the buffer holds) to `scene`, the faces from the first that changed to the last in one write (a
        dragged lamp in a million-triangle scan: 0.9 s for all of its vertices). False, nothing written,
        where the faces, their texture coordinates or textures differ, or a face gained or lost its area."""
        if not (scene.faces is previous.faces and scene.vertices.shape == previous.vertices.shape
                and scene.uv is previous.uv and same_textures(scene, previous)):
            return False
        drawn = scene.face_areas > 0
        if not np.array_equal(drawn, previous.face_areas > 0):
            return False
        with cores_for(len(scene.faces)):
            moved = faces_touching(np.asarray(scene.faces, np.int64), changed_rows((scene.vertices, previous.vertices)))
        changed = moved | changed_rows((scene.albedo, previous.albedo), (scene.emission, previous.emission))
        rows = np.flatnonzero(changed[drawn])
        if len(rows):
            first, last = int(rows[0]), int(rows[-1]) + 1
            vertices = scene_vertices(scene, faces=np.flatnonzero(drawn)[first:last])
            self.buffer.write(np.ascontiguousarray(vertices), offset=3 * first * vertices.shape[1] * 4)
        self.recoloured = None
        return True


def cube() -> np.ndarray:
    """(36, 6) float32: a unit cube in [-0.5, 0.5]^3 as triangles, position and face normal."""
    rows = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            normal = np.zeros(3)
            normal[axis] = sign
            u, v = np.eye(3)[(axis + 1) % 3], np.eye(3)[(axis + 2) % 3]
            centre = 0.5 * normal
            quad = [centre + 0.5 * (a * u + b * v) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            for i in (0, 1, 2, 0, 2, 3):
                rows.append(np.concatenate([quad[i], normal]))
    return np.asarray(rows, np.float32)

