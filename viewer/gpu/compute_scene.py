"""A VoxelGrid on the GPU for the compute solver: voxels, cells, clusters and light samples as SSBOs.

The tables are the numpy Tracer's (viewer/rays/raymarch.py), built by it and uploaded as they are: the
voxel arrays, and per cell (hash id order, `x + y N + z N^2`) its range of voxels and its
distance-field step. The clusters are transport._Visibility's: at 32^3 voxels and above, far voxel
pairs without an emitter share the visibility of their clusters. Bindings 0..6 (5 unused) are fixed
here and in shaders/compute_scene.glsl; programs use 7..15 for their own buffers.
"""

from __future__ import annotations


import moderngl
import numpy as np

from viewer.gpu.programs import set_uniforms
from viewer.rays.raymarch import Tracer
from viewer.scene import DirectionalLight
from viewer.physical.transport import SURFACE_OFFSET, clusters_of
from viewer.rays.voxels import VoxelGrid

LOOP_BUDGET = 60000
"""Loop iterations one shader invocation may run. llvmpipe gives all loops of a shader invocation batch
one counter of LP_MAX_TGSI_LOOP_ITERATIONS = 65535 back-edges and silently stops every loop once it is
spent, so long loops are cut into chunks of at most this many (worst-case) iterations per dispatch."""

SCENE_BINDINGS = {"voxel_position": 0, "voxel_normal": 1, "voxel_material": 2, "voxel_cluster": 3,
                  "cells": 4, "cluster_bits": 6}


def vec4s(values: np.ndarray, w: np.ndarray | float = 0.0, dtype=np.float32) -> bytes:
    """(K, 3) rows with a fourth column w, as std430 vec4 (or ivec4) bytes."""
    values = np.asarray(values)
    out = np.zeros((len(values), 4), dtype)
    out[:, :3] = values
    out[:, 3] = w
    return out.tobytes()


def chunk_ranges(costs, budget: int | None = None) -> list[tuple[int, int]]:
    """Consecutive ranges of items whose costs sum to at most `budget` (LOOP_BUDGET; an item above it
    goes alone); one empty range for no items, so that a pass still runs once."""
    budget = LOOP_BUDGET if budget is None else budget
    ranges, start, total = [], 0, 0
    for index, cost in enumerate(costs):
        if total + cost > budget and index > start:
            ranges.append((start, index))
            start, total = index, 0
        total += cost
    ranges.append((start, len(costs)))
    return ranges


def even_ranges(count: int, cost: int, budget: int | None = None, align: int = 1) -> list[tuple[int, int]]:
    """0..count in ranges of equal size (a multiple of `align`) costing at most `budget` (LOOP_BUDGET)."""
    budget = LOOP_BUDGET if budget is None else budget
    size = max(align, budget // max(cost, 1) // align * align)
    return [(start, min(start + size, count)) for start in range(0, count, size)] or [(0, 0)]


def cell_table(tracer: Tracer) -> np.ndarray:
    """(N^3, 4) uint32 per cell: first voxel, end voxel, the float bits of the safe step (voxels), 0."""
    table = np.zeros((len(tracer.free_steps), 4), np.uint32)
    table[:, 0] = tracer.first[:-1]
    table[:, 1] = tracer.first[1:]
    table[:, 2] = tracer.free_steps.astype(np.float32).view(np.uint32)
    return table


def emitter_mask(voxels: VoxelGrid) -> np.ndarray:
    return np.any(voxels.emission > 0, axis=1)


def same_geometry(a: VoxelGrid | None, b: VoxelGrid) -> bool:
    """Whether everything visibility and probe hits depend on is unchanged: the voxels' places, facings
    and areas, and which voxels emit (emitter pairs are traced exactly). Albedo, emitted colour and
    brightness, and the sun may differ."""
    if a is None or a.resolution != b.resolution or a.count != b.count or a.voxel_size != b.voxel_size:
        return False
    return (np.array_equal(a.lo, b.lo) and np.array_equal(a.coords, b.coords)
            and np.array_equal(a.position, b.position) and np.array_equal(a.normal, b.normal)
            and np.array_equal(a.area, b.area) and np.array_equal(emitter_mask(a), emitter_mask(b)))


class ComputeScene:
    """The GPU copy of one VoxelGrid's geometry (bindings 0..6) and of its lights (`set_lights`)."""

    def __init__(self, ctx: moderngl.Context, voxels: VoxelGrid):
        self.ctx = ctx
        self.voxels = voxels
        tracer = Tracer.build(voxels)
        self.clusters = clusters_of(voxels)
        c = self.clusters
        self.clustered = c.factor > 1
        self.cluster_words = -(-c.count // 32)
        self.buffers = {
            "voxel_position": ctx.buffer(vec4s(voxels.position, tracer.reach)),
            "voxel_normal": ctx.buffer(vec4s(voxels.normal, voxels.area)),
            "voxel_material": ctx.buffer(reserve=max(16 * voxels.count, 16)),
            "voxel_cluster": ctx.buffer(vec4s(c.cell, c.index, np.int32)),
            "cells": ctx.buffer(cell_table(tracer).tobytes()),
            # rows of uints, bit `column` of row `row` for row < column; written by the solver
            "cluster_bits": ctx.buffer(reserve=max(4 * c.count * self.cluster_words, 4) if self.clustered else 4),
        }
        self.cluster_buffers = {
            7: ctx.buffer(vec4s(c.position)),
            8: ctx.buffer(vec4s(c.normal)),
            9: ctx.buffer(vec4s(c.cluster_cell, 0, np.int32)),
        } if self.clustered else {}
        per_cell = int(np.diff(tracer.first).max(initial=0))
        steps = min(8 * voxels.resolution, int(np.ceil(2 * np.sqrt(3) * voxels.resolution)) + 2)
        self.march_iterations = steps * (1 + per_cell)
        """Worst-case loop iterations of one march (segment_clear, first_hit): a step is at least half a
        voxel, a segment inside the grid at most sqrt(3) N voxels long, and a step in an occupied cell
        loops over its voxels."""
        self.light_samples = self.emitters = None
        self.emitter_count = 0
        self.samples_per_emitter = np.zeros(0, np.int64)
        self.sun: DirectionalLight | None = None
        self.set_lights(voxels, None)

    @property
    def count(self) -> int:
        return self.voxels.count

    def set_lights(self, voxels: VoxelGrid, sun: DirectionalLight | None) -> None:
        """Albedo, emission and light samples of a grid with the same geometry, and the sun."""
        self.voxels = voxels
        self.sun = sun if sun is not None and np.any(sun.irradiance > 0) else None
        self.buffers["voxel_material"].write(vec4s(voxels.albedo, emitter_mask(voxels).astype(np.float32)))
        lights = voxels.lights
        # samples sorted by their voxel, so that each emitting voxel's samples are one range
        order = np.argsort(lights.voxel, kind="stable")
        samples = np.zeros((max(lights.count, 1), 3, 4), np.float32)
        samples[:lights.count, 0, :3] = lights.position[order]
        samples[:lights.count, 0, 3] = lights.area[order]
        samples[:lights.count, 1, :3] = lights.normal[order]
        samples[:lights.count, 2, :3] = lights.radiance[order]
        emitting, first = np.unique(lights.voxel[order], return_index=True)
        ranges = np.zeros((max(len(emitting), 1), 4), np.int32)
        ranges[:len(emitting), 0] = first
        ranges[:len(emitting), 1] = np.append(first[1:], lights.count)
        ranges[:len(emitting), 2] = emitting
        self.emitter_count = len(emitting)
        self.samples_per_emitter = (ranges[:len(emitting), 1] - ranges[:len(emitting), 0]).astype(np.int64)
        for name in ("light_samples", "emitters"):
            if getattr(self, name) is not None:
                getattr(self, name).release()
        self.light_samples = self.ctx.buffer(samples.tobytes())
        self.emitters = self.ctx.buffer(ranges.tobytes())

    def emitter_chunks(self, loops_per_sample: int, marches_per_emitter: int) -> list[tuple[int, int]]:
        """Ranges of emitting voxels per dispatch for a pass that loops over their light samples
        `loops_per_sample` times and marches `marches_per_emitter` times per voxel, within the loop
        budget less one march (to the sun)."""
        costs = loops_per_sample * self.samples_per_emitter + marches_per_emitter * self.march_iterations + 1
        return chunk_ranges(costs, max(LOOP_BUDGET - self.march_iterations, 1))

    def bind(self) -> None:
        for name, binding in SCENE_BINDINGS.items():
            self.buffers[name].bind_to_storage_buffer(binding)

    def dispatch(self, program, groups: tuple[int, int], buffers: dict[int, moderngl.Buffer], **uniforms) -> None:
        """Run a compute program over `groups` work groups with the scene's buffers and uniforms, the
        given buffers at their bindings, and a barrier after it (the next pass reads what this wrote)."""
        self.bind()
        for binding, buffer in buffers.items():
            buffer.bind_to_storage_buffer(binding)
        set_uniforms(program, **self.uniforms(), **uniforms)
        program.run(*groups)
        self.ctx.memory_barrier()

    def uniforms(self) -> dict:
        v = self.voxels
        h = float(v.voxel_size)
        return dict(grid_lo=tuple(float(x) for x in v.lo), voxel_size=h, grid_n=v.resolution,
                    voxel_count=v.count, march_limit=8 * v.resolution, surface_offset=SURFACE_OFFSET * h,
                    clustered=self.clustered, cluster_words=self.cluster_words)

    def light_uniforms(self) -> dict:
        """The sun, for the passes that gather direct light."""
        sun = self.sun
        return dict(sun_enabled=sun is not None,
                    sun_direction=tuple(float(x) for x in (sun.direction if sun else (0, 1, 0))),
                    sun_irradiance=tuple(float(x) for x in (sun.irradiance if sun else (0, 0, 0))),
                    sun_reach=3.0 * self.voxels.resolution * float(self.voxels.voxel_size))

    def release(self) -> None:
        for buffer in [*self.buffers.values(), *self.cluster_buffers.values(), self.light_samples, self.emitters]:
            if buffer is not None:
                buffer.release()
