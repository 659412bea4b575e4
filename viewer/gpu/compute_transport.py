"""The voxels' light on the GPU: viewer/physical/transport.py's direct light, visibility and bounces as passes.

Each pass takes a range of receivers (or of bitset rows) so that the solver can slice it to a frame
budget, and cuts its long loops into chunks within llvmpipe's loop budget (compute_scene.LOOP_BUDGET).
Buffers of K vec4 (rgb, w unused unless said): `direct` irradiance E_direct, `last` and `previous`
bounce (B_k and B_k-1, swapped after each bounce), `reflected` (the sum of the bounces), `accumulated`
(a bounce's sums between sender chunks), and `stats` (max |B_k|, max |reflected| as float bits).

The physical kernel's visibility: a bitset of the pairs that face each other and see each other, the
upper triangle of a symmetric K x K bit matrix (row i holds bits j > i from word (i + 1) / 32 on), K^2/16
bytes; or, where that does not fit one storage block, traced again in every bounce (`on-the-fly`).
"""

from __future__ import annotations

import moderngl
import numpy as np

from viewer.gpu.compute_scene import ComputeScene, even_ranges
from viewer.gpu.programs import ProgramLibrary
from viewer.rays import sun

VISIBILITY_MODES = ("auto", "bitset", "on-the-fly")
MAX_GROUPS = 65535
"""Work groups per dispatch dimension that every GL 4.3 implementation allows."""
RECEIVERS = 4
"""Receivers per invocation of compute_bounce.glsl."""


def rows_per_dispatch(row_length: int) -> int:
    """Rows of a pair table per dispatch: at most MAX_GROUPS, and about 2^26 pairs (one long dispatch
    can trip the watchdog of a desktop GPU)."""
    return max(1, min(MAX_GROUPS, (1 << 26) // max(row_length, 1)))


class ComputeTransport:
    def __init__(self, ctx: moderngl.Context, programs: ProgramLibrary, scene: ComputeScene):
        self.ctx, self.programs, self.scene = ctx, programs, scene
        k = scene.count
        self.buffers = {name: ctx.buffer(reserve=16 * max(k, 1))
                        for name in ("direct", "last", "previous", "reflected", "accumulated")}
        self.buffers["stats"] = ctx.buffer(reserve=16)
        first_word = (np.arange(k) + 1) >> 5
        row_length = -(-k // 32) - first_word
        self.row_words = -(-k // 32)
        self.bitset_words = int(row_length.sum())
        self._row_offsets = np.concatenate([[0], np.cumsum(row_length)[:-1]]).astype(np.uint32)
        self._bitset = self._bitset_rows = None
        self._placeholder = ctx.buffer(reserve=4)  # for the blocks a program declares but does not read
        self.bitset_ready = self.clusters_ready = False
        self.kernel, self.visibility = "physical", "bitset"

    def configure(self, kernel: str, visibility: str) -> None:
        """The kernel and visibility mode for the next passes; allocates the bitset when it is used."""
        limit = int(self.ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE", 1 << 27))
        if visibility == "auto":
            visibility = "bitset" if 4 * self.bitset_words <= limit else "on-the-fly"
        self.kernel, self.visibility = kernel, visibility
        if kernel == "physical" and visibility == "bitset" and self._bitset is None:
            if 4 * self.bitset_words > limit:
                raise ValueError(f"the visibility bitset of {self.scene.count} voxels needs "
                                 f"{4 * self.bitset_words >> 20} MiB, more than one storage block "
                                 f"({limit >> 20} MiB); use visibility='on-the-fly' or fewer voxels")
            self._bitset = self.ctx.buffer(reserve=max(4 * self.bitset_words, 4))
            self._bitset_rows = self.ctx.buffer(self._row_offsets.tobytes() if self.scene.count else bytes(4))
        for name in ("compute_cluster_visibility", "compute_visibility"):
            self.programs.get(name)
        self.programs.get("compute_direct", **self._direct_defines())
        self.programs.get("compute_bounce", **self._bounce_defines())

    @property
    def uses_bitset(self) -> bool:
        return self.kernel == "physical" and self.visibility == "bitset"

    @property
    def bitset_bytes(self) -> int:
        """GPU memory held by the visibility bitset (0 without one)."""
        return 4 * self.bitset_words if self._bitset is not None else 0

    def _kernel_defines(self) -> dict:
        return {"KERNEL_PAPER": int(self.kernel == "paper")}

    def _direct_defines(self) -> dict:
        return {**self._kernel_defines(), "SUN_SIDE": sun.SUN_SIDE}

    def _bounce_defines(self) -> dict:
        return {**self._kernel_defines(), "VISIBILITY_BITSET": int(self.visibility == "bitset")}

    def _dispatch(self, name: str, groups, buffers, defines: dict | None = None, **uniforms) -> None:
        self.scene.dispatch(self.programs.get(name, **(defines or {})), groups, buffers, **uniforms)

    # ---- first bounce --------------------------------------------------------------------------------
    def direct_chunks(self) -> list[tuple[int, int]]:
        """Emitting voxels per direct-light dispatch: a loop over their samples, and for the physical
        kernel a march to each."""
        return self.scene.emitter_chunks(1, int(self.kernel == "physical"))

    def direct(self, first: int, end: int) -> None:
        """E_direct and B1 = reflected for receivers first..end-1."""
        b, s, chunks = self.buffers, self.scene, self.direct_chunks()
        for n, (e0, e1) in enumerate(chunks):
            self._dispatch("compute_direct", (-(-(end - first) // 64), 1),
                           {9: s.light_samples, 10: s.emitters, 12: b["last"], 13: b["reflected"],
                            14: b["stats"], 15: b["direct"]}, self._direct_defines(),
                           first_item=first, first_emitter=e0, end_emitter=e1, first_chunk=n == 0,
                           last_chunk=n == len(chunks) - 1, **s.light_uniforms())

    # ---- visibility ----------------------------------------------------------------------------------
    def bit_ranges(self) -> list[tuple[int, int]]:
        """Bits of a visibility word traced per dispatch: 32 pairs a word, each a march."""
        return even_ranges(32, self.scene.march_iterations + 2)

    def cluster_rows(self, first: int, end: int) -> None:
        """Visibility between clusters, rows first..end-1 (32^3 voxels and above)."""
        s = self.scene
        for b0, b1 in self.bit_ranges():
            self._dispatch("compute_cluster_visibility", (-(-s.cluster_words // 64), end - first),
                           {**s.cluster_buffers, 10: s.buffers["cluster_bits"]},
                           cluster_count=s.clusters.count, first_row=first, first_bit=b0, end_bit=b1)

    def visibility_rows(self, first: int, end: int) -> None:
        """Bitset rows first..end-1."""
        for b0, b1 in self.bit_ranges():
            self._dispatch("compute_visibility", (-(-self.row_words // 64), end - first),
                           {7: self._bitset, 8: self._bitset_rows},
                           first_row=first, row_words=self.row_words, first_bit=b0, end_bit=b1)

    # ---- bounces -------------------------------------------------------------------------------------
    def sender_ranges(self) -> list[tuple[int, int]]:
        """Senders per bounce dispatch, from the worst-case loop iterations per sender of the four
        receivers of an invocation (compute_bounce.glsl): paper 1 + 4; bitset 5 below the diagonal
        and (4 + 32 * 9) / 32 in the rows; on the fly 1 + 4 marches."""
        if self.kernel == "paper":
            cost = 5
        elif self.visibility == "bitset":
            cost = 15
        else:
            cost = 9 + RECEIVERS * (self.scene.march_iterations + 1)
        return even_ranges(self.scene.count, cost, align=32)

    def bounce(self, first: int, end: int) -> None:
        """B_k+1 (into `previous`, swapped by `end_bounce`) and reflected += B_k+1, receivers first..end-1
        (first a multiple of RECEIVERS)."""
        b, chunks = self.buffers, self.sender_ranges()
        bitset = self._bitset or self._placeholder
        rows = self._bitset_rows or self._placeholder
        for n, (j0, j1) in enumerate(chunks):
            self._dispatch("compute_bounce", (-(-(end - first) // (RECEIVERS * 64)), 1),
                           {7: bitset, 8: rows, 11: b["last"],
                            12: b["previous"], 13: b["reflected"], 14: b["stats"], 15: b["accumulated"]},
                           self._bounce_defines(), first_item=first, end_item=end, first_sender=j0,
                           end_sender=j1, first_chunk=n == 0, last_chunk=n == len(chunks) - 1,
                           row_words=self.row_words)

    def end_bounce(self) -> None:
        self.buffers["previous"], self.buffers["last"] = self.buffers["last"], self.buffers["previous"]

    def clear_stats(self) -> None:
        self.buffers["stats"].clear()

    def converged(self, tolerance: float) -> bool:
        """transport.solve's test: the last bounce adds at most `tolerance` of the largest light so far."""
        bounce, total = np.frombuffer(self.buffers["stats"].read(8), np.float32)
        return bool(bounce <= tolerance * max(float(total), 1e-30))

    def add_tail(self) -> None:
        """The bounces not summed yet (transport._geometric_tail): each one the last times the ratio r of
        the last two, r / (1 - r) of the last in all."""
        last, previous = self.read("last"), self.read("previous")
        ratio = np.clip(last.sum(axis=0) / np.maximum(previous.sum(axis=0), 1e-30), 0.0, 0.9999)
        self.write("reflected", self.read("reflected") + last * (ratio / (1.0 - ratio)))

    # ---- reading back --------------------------------------------------------------------------------
    def read(self, name: str) -> np.ndarray:
        data = np.frombuffer(self.buffers[name].read(), np.float32).reshape(-1, 4)
        return data[:self.scene.count, :3].astype(np.float64)

    def write(self, name: str, values: np.ndarray) -> None:
        data = np.zeros((self.scene.count, 4), np.float32)
        data[:, :3] = values
        self.buffers[name].write(data.tobytes())

    def release(self) -> None:
        for buffer in [*self.buffers.values(), self._bitset, self._bitset_rows, self._placeholder]:
            if buffer is not None:
                buffer.release()
