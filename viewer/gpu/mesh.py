"""GPU geometry: the scene's triangles (flat per-face attributes) and the debug views' instanced shapes."""

from __future__ import annotations

from dataclasses import replace

import moderngl
import numpy as np

from viewer.scene import Scene

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

    def render(self, program: moderngl.Program, first: int = 0, count: int | None = None) -> None:
        """Draw the triangles, or `count` vertices from vertex `first` (one group's, see `group_runs`)."""
        count = self.vertex_count - first if count is None else count
        self.vertex_array(program).render(moderngl.TRIANGLES, vertices=count, first=first)

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
    `last`, this function's answer for an earlier scene: where `scene` has the same geometry arrays (a
    colour edit: Scene._recoloured), its colours are put in the same order on a copy of the reordered
    scene, which keeps its derived geometry (on a 68k-triangle scan, 0.1 s a colour edit less)."""
    if last is not None and all(getattr(scene, n) is getattr(last[0], n) for n in ("vertices", "faces", "face_group")):
        order = last[2]
        uv = last[1].uv if scene.uv is last[0].uv else scene.uv[order] if scene.uv is not None else None
        reordered = last[1]._recoloured(albedo=scene.albedo[order], emission=scene.emission[order], uv=uv,
                                        textures=scene.textures, sun=scene.sun)
        return scene, reordered, order
    area = np.bincount(scene.face_group, weights=scene.face_areas, minlength=len(scene.groups))
    order = np.lexsort((scene.face_group, area[scene.face_group]))
    uv = scene.uv[order] if scene.uv is not None else None
    return scene, replace(scene, faces=scene.faces[order], albedo=scene.albedo[order],
                          emission=scene.emission[order], face_group=scene.face_group[order], uv=uv), order


def group_runs(scene: Scene) -> list[tuple[int, int, int]]:
    """(group, first vertex, vertex count) of each run of faces of one group among the drawn
    (non-degenerate) faces, in order: what one draw of a textured group covers."""
    group = scene.face_group[scene.face_areas > 0]
    starts = np.flatnonzero(np.diff(group, prepend=-1) != 0)
    ends = np.append(starts[1:], len(group))
    return [(int(group[a]), 3 * int(a), 3 * int(b - a)) for a, b in zip(starts, ends)]


def vertex_albedo(scene: Scene) -> np.ndarray:
    """(F, 3) what the surface shader multiplies the texture's colour by: a textured face's albedo over
    its texture's mean colour (the shader's product is then the albedo at the fragment), else the albedo."""
    albedo = scene.albedo.copy()
    for index, texture in enumerate(scene.textures):
        if texture is not None:
            mean = texture.mean
            chosen = scene.face_group == index
            albedo[chosen] = np.where(mean > 0, albedo[chosen] / np.where(mean > 0, mean, 1.0), albedo[chosen])
    return albedo


def scene_vertices(scene: Scene, columns: int = 14) -> np.ndarray:
    """(3F, columns) float32 over the faces with an area, three vertices a face: position, the face's
    normal, vertex albedo and emission, texture coordinate (14 columns: SceneMesh's layout; the rest left
    for the caller). Written column by column into the float32 array: made in float64 and converted, a
    68k-triangle scan's took 33 ms, twice after every lamp move (this mesh's and the lightmap's)."""
    keep = scene.face_areas > 0
    out = np.empty((int(keep.sum()), 3, columns), np.float32)
    out[..., 0:3] = scene.triangles[keep]
    for start, per_face in ((3, scene.face_normals), (6, vertex_albedo(scene)), (9, scene.emission)):
        out[..., start:start + 3] = per_face[keep][:, None, :]
    out[..., 12:14] = face_uv(scene)[keep]
    return out.reshape(-1, columns)


def face_uv(scene: Scene) -> np.ndarray:
    """(F, 3, 2) the faces' corners' texture coordinates (zeros for a scene without textures)."""
    return scene.uv if scene.uv is not None else np.zeros((len(scene.faces), 3, 2))


def same_triangles(a: Scene, b: Scene) -> bool:
    """Whether two scenes have the same triangles in the same order (their colours may differ)."""
    if a.faces is b.faces and a.vertices is b.vertices:
        return True
    return (a.faces.shape == b.faces.shape and a.vertices.shape == b.vertices.shape
            and np.array_equal(a.faces, b.faces) and np.array_equal(a.vertices, b.vertices))


def face_colours(scene: Scene) -> np.ndarray:
    """(F, 6) float32: each drawn face's albedo (`vertex_albedo`) and emission, the attributes after position
    and normal in both vertex layouts (SceneMesh's and the lightmap's), which a colour edit writes alone
    (`write_colours`)."""
    keep = scene.face_areas > 0
    return np.concatenate([vertex_albedo(scene)[keep], scene.emission[keep]], axis=1).astype(np.float32)


def write_colours(buffer: moderngl.Buffer, colours: np.ndarray, held: np.ndarray | None, stride: int) -> np.ndarray:
    """Write the faces' `colours` (`face_colours`) into a vertex buffer of `stride` bytes a vertex (position
    and normal first), three vertices a face, where they differ from `held`, the colours it holds (None:
    unknown): the faces from the first that changed to the last, in one write (a lamp's colour or a wall's
    is a few faces, where all of a 68k-triangle scan's took 6 ms a buffer). Returns `colours`, held now."""
    if held is None or held.shape != colours.shape:
        changed = np.arange(len(colours))
    else:
        changed = np.flatnonzero((colours != held).any(axis=1))
    if len(changed):
        first, last = int(changed[0]), int(changed[-1]) + 1
        vertices = np.repeat(colours[first:last], 3, axis=0)
        buffer.write_chunks(vertices.tobytes(), 24 + 3 * first * stride, stride, len(vertices))
    return colours


class SceneMesh(TriangleBuffer):
    """The scene as a non-indexed triangle list: every vertex carries its face's normal, albedo and
    emission (flat shading, one material per face) and its texture coordinate. Degenerate faces are
    dropped (no normal)."""

    def __init__(self, ctx: moderngl.Context, scene: Scene):
        super().__init__(ctx)
        vertices = self._vertices(scene)
        self.vertex_count = len(vertices)
        self.buffer = ctx.buffer(np.ascontiguousarray(vertices))   # read in place, not copied
        self.colours: np.ndarray | None = None   # `face_colours` the buffer holds, once a colour edit wrote them

    @staticmethod
    def _vertices(scene: Scene) -> np.ndarray:
        return scene_vertices(scene)

    @staticmethod
    def remade(old: "SceneMesh | None", ctx: moderngl.Context, scene: Scene, previous: Scene | None) -> "SceneMesh":
        """The mesh of `scene`: `old` (made for `previous`) with the new colours written into its buffer
        where the triangles are the same (a colour edit: its vertex arrays kept; only the colours where the
        texture coordinates are the same too), else a new one (`old` released)."""
        if old is not None and previous is not None and same_triangles(scene, previous):
            if scene.uv is previous.uv:   # the same array: `in_draw_order` keeps it across colour edits
                old.colours = write_colours(old.buffer, face_colours(scene), old.colours, 56)
            else:
                old.buffer.write(np.ascontiguousarray(SceneMesh._vertices(scene)))
                old.colours = None
            return old
        if old is not None:
            old.release()
        return SceneMesh(ctx, scene)


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

