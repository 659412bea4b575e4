"""VoxelGrid -> ProbeGrid in one shot: the trained network (ONNX) run by onnxruntime on the CPU.

A model is a `.onnx` file with a JSON card beside it (`models/<name>.json`): what the network reads
(`viewer.neural.encoding` version, voxel resolution), the probe lattice it writes, how it was trained, its
measured error and the file's sha256. Anything that does not match (missing file, corrupt bytes, another
encoding version, unexpected tensor shapes) is a `ModelError` with one readable line: the command line
turns it into exit status 2, the viewer into a message and a fall-back to the compute solver.
"""

from __future__ import annotations

import time
from dataclasses import replace
from functools import partial
from typing import Callable
from pathlib import Path

import numba
import numpy as np

from viewer.rays.voxel_rays import VoxelRays
from viewer.neural import encoding
from viewer.neural.card import ModelCard, ModelError, file_sha256, open_session  # noqa: F401 - the source's API
from viewer.neural.domain import Shape, measure, outside
from viewer.neural.encoder import Encoder
from viewer.neural.network_feed import FILTERED, WallTaps, feed, wall_taps
from viewer.neural.network_tail import HEAD, Tail, fed_names, run_graph, run_overlapped
from viewer.probes.grid import ProbeGrid
from viewer.resources import DEFAULT_MODEL
from viewer.scene import Scene
from viewer.rays.voxel_faces import FaceVoxels
from viewer.rays.voxels import VoxelAlbedo, VoxelGrid, voxelize

OUTPUTS = 19
"""Per probe and colour pass: 9 SH of all the light, 9 of the reflected light, 1 validity logit."""
UNPACK_RUN = 256
"""Probes a task of `unpack` takes."""


def clock_now() -> float:
    """Seconds on `CLOCK`, for the stages' timings."""
    return CLOCK()


CLOCK = time.perf_counter
"""What the stages are timed with; `python -m viewer.bench.neural` swaps in time.thread_time to count the
CPU time of each stage alone (everything here runs on the calling thread) on a machine shared with
other work."""


class NeuralField:
    """A loaded model: `predict` maps voxels to probes."""

    def __init__(self, model: str | Path = DEFAULT_MODEL, threads: int = 1):
        self.card = ModelCard.read(Path(model))
        if file_sha256(self.card.path) != self.card.sha256:
            raise ModelError(f"{self.card.path.name}: file does not match its card's sha256 (corrupt or replaced)")
        version = self.card.data["inputs"]["encoding_version"]
        if version not in encoding.VERSION_CHANNELS:
            raise ModelError(f"{self.card.path.name} was trained on encoding version {version}, "
                             f"this viewer encodes versions {', '.join(map(str, encoding.VERSION_CHANNELS))}")
        self.channels = encoding.VERSION_CHANNELS[version]
        """The encoding's features the network reads (the first this many: an older version's)."""
        self.session = open_session(self.card.path, threads)
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        encoded = [i for i in inputs if i.name not in FILTERED]
        if len(encoded) not in (1, 2) or any(i.shape[1] != self.channels for i in encoded):
            raise ModelError(f"{self.card.path.name}: expects inputs {', '.join(str(i.shape) for i in inputs)}, "
                             f"the encoding gives (3, {self.channels}, M, M, M)")
        if len(outputs) != 1 or outputs[0].shape[1] != OUTPUTS:
            raise ModelError(f"{self.card.path.name}: gives outputs {outputs[0].shape}, expected (3, {OUTPUTS}, M, M, M)")
        self.tail = Tail.of(self.card.data) if outputs[0].name == HEAD else None
        """The arithmetic after the network's head, where its graph ends there (viewer.neural.network_tail)."""
        if outputs[0].name == HEAD and self.tail is None:
            raise ModelError(f"{self.card.path.name}: its graph ends at its head, but its card has no tail gains")
        self.input_names = fed_names([i.name for i in inputs], self.tail)
        """The encoded inputs first, then those made from them (`network_feed.feed`): the same through asinh
        where the graph does not compute it, its seen filter's products where it or its tail reads them."""
        self.kernels = None
        """(9, 27) the seen filter's kernels from the card, for a network that takes their products."""
        if any(name in FILTERED for name in self.input_names):
            try:
                self.kernels = np.asarray(self.card.data["inputs"]["filtered"]["kernels"], np.float32).reshape(9, 27)
            except (KeyError, TypeError, ValueError) as exc:
                raise ModelError(f"{self.card.path.name}: takes its seen filter's products, but its card has no "
                                 f"9 x 27 kernels for them ({exc})") from None
        self._encoder: Encoder | None = None
        self._output: np.ndarray | None = None       # the network's last output, and per colour pass
        self._output_keys: list = [None] * 3         # the (encoder, revision) of the inputs it ran on
        self._fed: dict | None = None                # the last run's feed (`network_feed.feed`'s previous)
        self._valid: tuple | None = None
        """(encoder, blockers, valid): the validity the network voted for the geometry's first probes. A
        probe's validity is where it stands (inside a solid or not), so a colour edit keeps it: a
        borderline vote that flipped with a wall's colour cost the renderer a new lattice's weights
        (0.2 s) and an install (16 ms) on that edit."""
        self.passes_run = 0
        """Colour passes the network ran for in the last `predict` (0 to 3)."""

    @property
    def resolution(self) -> int:
        return self.card.probes

    def predict(self, voxels: VoxelGrid, sun, lo, hi, blockers: VoxelRays | None, include_emitted: bool = True,
                timings: dict | None = None, resolution: int | None = None, reuse: bool = True) -> ProbeGrid:
        """Probes over [lo, hi]: all the incident light (`include_emitted`, as `sample` and Mitsuba see
        it) or the light reflected by surfaces alone (what the renderer samples). `blockers` cast the
        direct light's shadows: `encoding.occluders` of the scene the voxels were made from, the same
        object while its triangles stay the same. `resolution` other than the card's runs the same
        convolutional network on another lattice (for timing; its accuracy there is not what the card
        measured).

        The encoder of the lattice is kept (viewer.neural.encoder), so a call after an edit recomputes only
        what the edit changed, and the network runs only for the colour passes whose inputs changed
        (none after a lamp's colour or intensity edit: the scale-out makes those exactly linear).
        `reuse=False` encodes and runs everything afresh: what a new scene costs."""
        m = resolution or self.resolution
        clock = clock_now()
        encoder = (self.encoder(lo, hi, m) if reuse
                   else Encoder(lo, hi, m, self.card.seen_rays, self.card.direct_shadows))
        enc = encoder.encode(voxels, sun, blockers)
        encoded = clock_now()
        out = self._network(encoder, enc.inputs) if reuse else self.run(enc.inputs, partial(wall_taps, encoder.seen))
        ran = clock_now()
        computed = include_emitted and not encoder.direct_shadows   # the network's direct light is unshadowed
        grid = unpack(out, enc.scale, enc.lo, enc.hi, include_emitted and not computed)
        unpacked = clock_now()
        if computed:   # all the light: the probes' direct light with its shadows, added
            direct = encoding.probe_direct(voxels, sun, enc.lo, enc.hi, m, blockers).reshape(grid.coefficients.shape)
            grid = replace(grid, coefficients=(grid.coefficients + direct).astype(np.float32))
        if reuse and blockers is not None:   # the geometry's first vote on which probes are valid stays
            if self._valid is not None and self._valid[0] is encoder and self._valid[1] is blockers:
                grid = replace(grid, valid=self._valid[2])
            else:
                self._valid = (encoder, blockers, grid.valid)
        if timings is not None:
            rays = encoder.ray_seconds   # the seen rays, cast once per geometry (viewer/neural/seen.py)
            timings.update(encode=encoded - clock - rays, rays=rays, network=ran - encoded, unpack=unpacked - ran)
            if computed:
                timings["direct"] = clock_now() - unpacked
        return grid

    def forget(self) -> None:
        """Drop the kept encoder and network outputs: the next prediction costs what a new scene does."""
        self._encoder, self._output, self._output_keys, self._valid = None, None, [None] * 3, None

    def encoder(self, lo, hi, resolution: int) -> Encoder:
        """The encoder of this lattice, kept from the last call when the lattice is the same."""
        if self._encoder is None or not self._encoder.fits(lo, hi, resolution):
            self._encoder = Encoder(lo, hi, resolution, self.card.seen_rays, self.card.direct_shadows)
        return self._encoder

    def _network(self, encoder: Encoder, inputs: np.ndarray) -> np.ndarray:
        """The network's (3, 19, M, M, M) output, run for the colour passes whose inputs differ from the
        ones it last ran on (`Encoder.revisions`); the others keep their output."""
        keys = [(encoder.serial, int(r)) for r in encoder.revisions]
        stale = [c for c in range(3) if self._output is None or self._output_keys[c] != keys[c]
                 or self._output.shape[2:] != inputs.shape[2:]]
        walls = partial(wall_taps, encoder.seen)   # made where the filter needs them (`run_overlapped`)
        if len(stale) == 3:
            self._output = self.run(inputs, walls)
        elif stale:
            fresh = self.run(np.ascontiguousarray(inputs[stale]), walls)
            self._output[stale] = fresh   # private: the grids unpacked from it hold copies
        self.passes_run = len(stale)
        self._output_keys = keys
        return self._output

    def run(self, inputs: np.ndarray, walls: "WallTaps | Callable[[], WallTaps | None] | None" = None) -> np.ndarray:
        """The network on encoded inputs (passes, CHANNELS, M, M, M): its raw output (passes, 19, M, M, M);
        its seen filter stopped at the `walls` of the inputs' geometry (`network_feed.wall_taps`, or what
        makes them)."""
        self.passes_run = len(inputs)
        if inputs.shape[1] != self.channels:
            inputs = np.ascontiguousarray(inputs[:, :self.channels])
        if self.tail is None:
            fed = feed(self.input_names, inputs, self.kernels, walls() if callable(walls) else walls, self._fed)
            out = run_graph(self.session, fed, self.tail)
        else:
            fed, out = run_overlapped(self.session, inputs, self.kernels, walls, self._fed, self.tail)
        # its compressed rows serve the next run where the inputs stay the same: only inputs nobody can
        # change in place (the encoder's are read-only), so that equal rows are truly the same values
        self._fed = None if inputs.flags.writeable else fed
        return out

    def solve(self, scene: Scene, include_emitted: bool = True, timings: dict | None = None) -> ProbeGrid:
        """Voxelize the scene at the card's resolution, list its occluders, and predict over its bounds."""
        clock = clock_now()
        voxels = voxelize(scene, self.card.voxels)
        blockers = encoding.occluders(scene, voxels)
        if timings is not None:
            timings["voxelize"] = clock_now() - clock
        lo, hi = scene.bounds
        return self.predict(voxels, scene.sun, lo, hi, blockers, include_emitted, timings)


class SceneVoxels:
    """A scene's geometry voxelized for the network, with each voxel's share of each face
    (viewer.rays.voxels.Voxelization): the voxels of any scene with the same triangles, whatever its colours,
    are one sparse product away (`voxels_of`). Kept per (voxel, face) (viewer.rays.voxel_faces), so that the
    voxels of a scene where some faces moved (a dragged lamp) are made from the `previous` ones and the
    moved faces alone. With what casts the encoding's shadows (`encoding.occluders`, listed afresh: they
    are the triangles) and the triangles' shape for the domain check."""

    def __init__(self, scene: Scene, resolution: int, previous: "SceneVoxels | None" = None):
        clock = clock_now()
        self.vertices, self.faces = scene.vertices, scene.faces
        self.bounds = scene.bounds
        self.pairs = previous.pairs.moved(scene) if previous is not None and previous.resolution == resolution else None
        self.voxelized_afresh = self.pairs is None
        """Whether all the faces were voxelized (else only those that moved)."""
        self.pairs = self.pairs or FaceVoxels.of(scene, resolution)
        self.voxelization = self.pairs.voxelization(scene)
        self.shape = Shape.of(scene)
        self._grid = self.voxelization.grid   # its colours are the faces' shares', as every edit's come
        self._emission = scene.emission   # what the voxels' emission and lights were made from
        self._albedo = VoxelAlbedo(self.voxelization.faces, self.voxelization.tint, scene, self._grid.albedo)
        self.blockers = encoding.occluders(scene, self._grid, None if previous is None else previous.blockers)
        """The occluders of these triangles, one object for every colour edit (the encoder keeps its
        shadows while it is given the same)."""
        self.seconds = clock_now() - clock
        """How long voxelizing and listing the occluders took."""

    @property
    def resolution(self) -> int:
        return self.pairs.resolution

    def fits(self, scene: Scene) -> bool:
        """Whether `scene` has the triangles these voxels were made from (a colour edit keeps them)."""
        return _same(self.vertices, scene.vertices) and _same(self.faces, scene.faces)

    def voxels_of(self, scene: Scene) -> VoxelGrid:
        """The voxels with `scene`'s albedo and emission (area-weighted per voxel, as `voxelize` gives
        them, to round-off); the same object while the colours stay the same."""
        albedo = self._albedo.of(scene)   # the voxels of the faces recoloured alone summed again
        if not _same(self._emission, scene.emission):
            grid = self.voxelization.grid
            lights = grid.lights
            if lights.face is not None and lights.count:
                lights = replace(lights, radiance=scene.emission[lights.face])
            self._grid = replace(grid, albedo=albedo, emission=self.voxelization.faces @ scene.emission,
                                 lights=lights)
            self._emission = scene.emission
        elif albedo is not self._grid.albedo:
            # an albedo edit: the emission and lights as they were (0.7 ms of a 68k-triangle scan's)
            self._grid = replace(self._grid, albedo=albedo)
        return self._grid


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a is b or (a.shape == b.shape and np.array_equal(a, b))


class NeuralGI:
    """The neural field on a scene and its edits, as `viewer.physical.gi.PhysicalGI` is for the solver: the
    voxels of the scene's geometry are kept (`SceneVoxels`), so a colour edit (an albedo, a lamp's
    colour or intensity) recolours them instead of voxelizing, and the field's encoder recomputes only
    what the edit changed (viewer.neural.encoder). A moved lamp or a new scene is voxelized again and its
    occluders listed again (so the encoder traces its shadows again): `prepare` (which can run on a
    worker thread) and `install`, or `update` for both."""

    def __init__(self, field: NeuralField, resolution: int | None = None, voxels: int | None = None):
        self.field = field
        self.resolution = resolution or field.resolution
        """Probes per axis: the card's, or another lattice divisible by 2^levels (for timing)."""
        self.voxel_resolution = voxels or field.card.voxels
        """Voxels per axis the encoding reads: the card's, or another (for timing)."""
        self.voxels: SceneVoxels | None = None

    def needs_voxelizing(self, scene: Scene) -> bool:
        return self.voxels is None or not self.voxels.fits(scene)

    def prepare(self, scene: Scene) -> SceneVoxels:
        """Voxelize `scene`, from the installed voxels when only some faces moved (changes nothing here:
        safe on a worker thread)."""
        return SceneVoxels(scene, self.voxel_resolution, self.voxels)

    def install(self, voxels: SceneVoxels) -> None:
        self.voxels = voxels

    def predict(self, scene: Scene, include_emitted: bool = False, timings: dict | None = None) -> ProbeGrid:
        """The probes of `scene`, whose geometry is the installed one. `timings` gets `recolour` (the
        voxels' colours) and the network's stages (`NeuralField.predict`)."""
        clock = clock_now()
        grid = self.voxels.voxels_of(scene)
        if timings is not None:
            timings["recolour"] = clock_now() - clock
        lo, hi = self.voxels.bounds
        return self.field.predict(grid, scene.sun, lo, hi, self.voxels.blockers, include_emitted, timings,
                                  self.resolution)

    def outside(self, scene: Scene) -> list[str]:
        """Why `scene` (with the installed geometry) lies outside the model's training domain
        (viewer.neural.domain; empty when it does not)."""
        return outside(scene, self.field.card.domain, measure(scene, self.voxels.shape))

    def update(self, scene: Scene, include_emitted: bool = False, timings: dict | None = None) -> ProbeGrid:
        """Voxelize when the geometry changed, then predict."""
        if self.needs_voxelizing(scene):
            self.install(self.prepare(scene))
            if timings is not None:
                timings["voxelize"] = self.voxels.seconds
        return self.predict(scene, include_emitted, timings)


def unpack(out: np.ndarray, scale: np.ndarray, lo, hi, include_emitted: bool) -> ProbeGrid:
    """The network's (3, 19, M, M, M) output in units of each pass's scale -> a ProbeGrid: SH (M, M, M,
    9, 3) in radiance units (all the light, or the reflected light alone) and the validity vote of the
    three passes; one compiled pass over the output."""
    m = out.shape[-1]
    coefficients = np.empty((m ** 3, 9, 3), np.float32)
    valid = np.empty(m ** 3, np.bool_)
    _unpack(out.reshape(3, OUTPUTS, -1), 0 if include_emitted else 9, np.asarray(scale, np.float32),
            coefficients, valid)
    return ProbeGrid(lo=lo, hi=hi, coefficients=coefficients.reshape(m, m, m, 9, 3), valid=valid.reshape(m, m, m))


@numba.njit(cache=True, nogil=True, parallel=True)
def _unpack(out, first, scale, coefficients, valid):
    """coefficients[p, k, c] = out[c, first + k, p] x scale[c]; valid[p]: the mean logit of the passes
    is positive. A run of probes a task, each probe's 27 numbers written together: 0.33 -> 0.17 ms for a
    24^3 lattice, where one thread wrote a colour's coefficients at a time."""
    count = out.shape[2]
    for run in numba.prange((count + UNPACK_RUN - 1) // UNPACK_RUN):
        for p in range(run * UNPACK_RUN, min(count, (run + 1) * UNPACK_RUN)):
            row = coefficients[p]
            for k in range(9):
                row[k, 0] = out[0, first + k, p] * scale[0]
                row[k, 1] = out[1, first + k, p] * scale[1]
                row[k, 2] = out[2, first + k, p] * scale[2]
            valid[p] = out[0, 18, p] + out[1, 18, p] + out[2, 18, p] > 0.0
