"""The renderer's two debug views of the GI data itself: `voxels` (the voxel grid as cubes, coloured by
albedo or by outgoing radiance) and the spheres of `probes` (each valid probe shaded by its SH,
shaders/probe_spheres.glsl), drawn as instances over the scene."""

from __future__ import annotations

import moderngl
import numpy as np

from viewer.gpu.camera import clip_range, gl_bytes, perspective, view_matrix
from viewer.gpu.mesh import cube
from viewer.gpu.programs import ProgramLibrary, set_uniforms
from viewer.probes.grid import ProbeGrid
from viewer.scene import Camera
from viewer.rays.voxels import VoxelGrid


class DebugViews:
    """Instance buffers of the probes and voxels, and their draws."""

    def __init__(self, ctx: moderngl.Context, programs: ProgramLibrary):
        self.ctx = ctx
        self.programs = programs
        self._cube = ctx.buffer(cube().tobytes())
        self._quad = ctx.buffer(np.array([-1, -1, 1, -1, -1, 1, 1, 1], np.float32).tobytes())
        self._probe_instances = None
        self._voxel_instances = None
        self._voxel_data = None
        self._voxel_key = None

    def set_probes(self, probes: ProbeGrid | None) -> None:
        self._release_instances("_probe_instances")
        if probes is not None:
            index = np.argwhere(probes.valid if probes.valid.any() else np.ones_like(probes.valid)).astype(np.int32)
            self._probe_instances = (self.ctx.buffer(index.tobytes()), len(index))

    def set_voxels(self, voxels: VoxelGrid | None, radiance: np.ndarray | None = None) -> None:
        """Voxels for the `voxels` view, with their outgoing radiance (K, 3) if known."""
        self._release_instances("_voxel_instances")
        self._voxel_data = None
        if voxels is None or voxels.count == 0:
            return
        cells = voxels.cells()
        _, inverse = np.unique(voxels.hash_id, return_inverse=True)   # the cells' order, as in cells()
        if radiance is not None:  # area-weighted mean over the voxels (facings) of each cell
            weighted = np.asarray(radiance, np.float64) * voxels.area[:, None]
            total = np.stack([np.bincount(inverse, weighted[:, c]) for c in range(3)], axis=1)
            radiance = total / cells["area"][:, None]
        self._voxel_data = (cells["center"], cells["albedo"], radiance, voxels.voxel_size)
        self._voxel_key = None

    def radiance_shown(self, voxel_color: str) -> bool:
        """Whether the voxels view shows radiance (asked for, and known) rather than albedo."""
        return voxel_color == "radiance" and self._voxel_data is not None and self._voxel_data[2] is not None

    def draw_probes(self, camera: Camera, aspect: float, probes: ProbeGrid, probe_units: list[int],
                    box: tuple[np.ndarray, np.ndarray], bounds, radius: float) -> None:
        """Spheres of `radius` probe spacings at the probes; `box`: the probe textures' lo and hi."""
        if self._probe_instances is None:
            return
        program = self.programs.get("probe_spheres")
        buffer, count = self._probe_instances
        m = probes.resolution
        near, far = clip_range(camera, *bounds)
        set_uniforms(program, view=gl_bytes(view_matrix(camera)),
                     projection=gl_bytes(perspective(camera.fov, aspect, near, far)), probe_sh=probe_units,
                     probe_lo=tuple(box[0]), probe_hi=tuple(box[1]), probe_count=(m, m, m),
                     sphere_radius=radius * float(np.min(probes.spacing)))
        array = self.ctx.vertex_array(program, [(self._quad, "2f", "in_corner"), (buffer, "3i/i", "in_probe")])
        array.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=count)
        array.release()

    def draw_voxels(self, view_proj: np.ndarray, voxel_color: str) -> None:
        if self._voxel_data is None:
            return
        centers, albedo, radiance, size = self._voxel_data
        shown = self.radiance_shown(voxel_color)
        if self._voxel_instances is None or self._voxel_key != shown:
            self._release_instances("_voxel_instances")
            colors = radiance if shown else albedo
            data = np.concatenate([centers, colors], axis=1).astype(np.float32)
            self._voxel_instances = (self.ctx.buffer(data.tobytes()), len(data))
            self._voxel_key = shown
        program = self.programs.get("voxel_cubes")
        buffer, count = self._voxel_instances
        set_uniforms(program, view_proj=gl_bytes(view_proj), cube_size=size, shade=not shown)
        array = self.ctx.vertex_array(program, [(self._cube, "3f 3f", "in_position", "in_normal"),
                                                (buffer, "3f 3f/i", "in_center", "in_color")])
        array.render(moderngl.TRIANGLES, vertices=36, instances=count)
        array.release()

    def _release_instances(self, name: str) -> None:
        instances = getattr(self, name)
        if instances is not None:
            instances[0].release()
        setattr(self, name, None)

    def release(self) -> None:
        self._release_instances("_probe_instances")
        self._release_instances("_voxel_instances")
        self._cube.release()
        self._quad.release()
