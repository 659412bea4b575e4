"""Dataset rooms -> training tensors for ProbeNet: encoded inputs and scaled targets, cached on disk per
shard and read back memory-mapped, so that thousands of rooms train in a few gigabytes of memory.

    python -m viewer.training.samples --data data/gi-v2 [--probes 24]   # builds the caches (optional:
                                                                          # training builds them too)

A room's inputs come from `viewer.neural.encoding.encode` on its voxels (the same call the viewer makes); its
targets are the ground-truth SH of the dataset (invalid probes filled), per colour channel, divided by
the encoding's scale, so that inputs and targets are in the same units:

- `targets` (18): all the incident light (9), then the light reflected by surfaces alone (9), from the
  dataset's truth (the physical solver for format-2 datasets: deterministic, biased on the reflected part);
- `unbiased` (9): the reflected light from Mitsuba's probes where the room has them beside the truth
  (`--mitsuba-directions`: noisy, unbiased), zeros elsewhere; `has_unbiased` says which rooms.

Encoding a room means voxelizing it (0.02-0.1 s at 24^3), so every shard (200 rooms) is encoded once by a
pool of processes and kept in `<data>/cache/<split>/`; a cache is keyed by the shard's name and size,
so the rooms a running dataset command adds later are encoded when they are packed, and nothing else is.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import time
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from viewer.neural import encoding
from viewer.probes.grid import fill_invalid
from viewer.rays.voxels import voxelize

ENCODING_VOXELS = 24
"""Voxel resolution the encoder reads, recorded in the model card: the probe lattice's (24^3), so that a
lattice cell holds one voxel's surface and the features are as sharp as the targets."""
CACHE_VERSION = 5
"""Bump when what a cache holds changes, so that stale caches are rebuilt."""


class Stacked:
    """The rows of several arrays (the memory-mapped caches of a split's shards) read as one array:
    `len`, `shape`, `dtype`, iteration, and indexing by an int, a slice or an array of rows (a copy)."""

    def __init__(self, parts, order: np.ndarray | None = None):
        self.parts = list(parts)
        self._starts = np.cumsum([0] + [len(p) for p in self.parts])
        self.order = np.arange(self._starts[-1]) if order is None else np.asarray(order, np.int64)

    def __len__(self) -> int:
        return len(self.order)

    @property
    def shape(self) -> tuple:
        return (len(self),) + tuple(self.parts[0].shape[1:])

    @property
    def dtype(self):
        return self.parts[0].dtype

    def select(self, index) -> "Stacked":
        """These rows (an index array or a slice), without copying anything."""
        return Stacked(self.parts, self.order[index])

    @staticmethod
    def join(a: "Stacked", b: "Stacked") -> "Stacked":
        return Stacked(a.parts + b.parts, np.concatenate([a.order, b.order + a._starts[-1]]))

    def _row(self, row: int) -> np.ndarray:
        part = int(np.searchsorted(self._starts, row, side="right")) - 1
        return np.asarray(self.parts[part][row - self._starts[part]])

    def __getitem__(self, index):
        if isinstance(index, (int, np.integer)):
            return self._row(int(self.order[index]))
        return np.stack([self._row(int(r)) for r in self.order[index]]) if len(self.order[index]) else \
            np.zeros((0,) + self.shape[1:], self.dtype)

    def __iter__(self):
        for i in range(len(self)):
            yield self[i]

    def __array__(self, dtype=None, copy=None):
        out = self[np.arange(len(self))]
        return out.astype(dtype) if dtype is not None else out


@dataclass
class Samples:
    inputs: Stacked
    """(S, 3, CHANNELS, M, M, M) float16: room s, colour channel c."""
    targets: Stacked
    """(S, 3, 18, M, M, M) float16: the truth's SH / scale: all the incident light (9), then the light
    reflected by surfaces alone (9)."""
    valid: Stacked
    """(S, M, M, M) bool."""
    scale: np.ndarray
    """(S, 3) float32."""
    names: list[str]
    unbiased: Stacked | None = None
    """(S, 3, 9, M, M, M) float16: Mitsuba's reflected light / scale where `has_unbiased`, else zeros."""
    has_unbiased: np.ndarray | None = None
    """(S,) bool."""
    links: Stacked | None = None
    """(S, 3, M, M, M) bool: where the seen filter stops (`encoding.Encoding.links`)."""

    def __len__(self) -> int:
        return len(self.names)

    def physical(self, normalized: np.ndarray) -> np.ndarray:
        """(S, 3, K, M, M, M) scaled SH -> (S, M, M, M, K, 3) in radiance units."""
        return (normalized * self.scale[:, :, None, None, None, None]).transpose(0, 3, 4, 5, 2, 1)

    def subset(self, index) -> "Samples":
        index = np.asarray(index, np.int64)
        return Samples(self.inputs.select(index), self.targets.select(index), self.valid.select(index),
                       self.scale[index], [self.names[i] for i in index],
                       self.unbiased.select(index) if self.unbiased is not None else None,
                       self.has_unbiased[index] if self.has_unbiased is not None else None,
                       self.links.select(index) if self.links is not None else None)


PAPER_TRAINING = ("paper-train-1", "paper-train-2", "paper-train-3", "paper-train-4", "paper-train-5")
"""The paper's five training layouts join the procedural rooms in training; `paper-test` (held out) and
`cornell` (paper-test without its new sphere and pink wall) never do."""


def training_split(root: Path, resolution: int, quiet: bool = False, voxels: int = ENCODING_VOXELS,
                   encode: bool = True, limit: int = 0) -> Samples:
    """The procedural `train` split (its first `limit` rooms, when given) plus the paper's training
    layouts."""
    train = load_split(root, "train", resolution, quiet=quiet, voxels=voxels, encode=encode, rooms=limit)
    if limit:
        train = train.subset(np.arange(min(limit, len(train))))
    paper = load_split(root, "paper", resolution, quiet=quiet, voxels=voxels)
    return concat(train, paper, keep=[n for n in paper.names if n in PAPER_TRAINING])


def concat(a: Samples, b: Samples, keep=None) -> Samples:
    """a followed by b's rooms named in `keep` (all of b by default)."""
    b = b.subset([i for i, n in enumerate(b.names) if keep is None or n in keep])

    def join(x, y):
        return Stacked.join(x, y) if x is not None and y is not None else None

    has = None if a.has_unbiased is None or b.has_unbiased is None else np.concatenate([a.has_unbiased, b.has_unbiased])
    return Samples(Stacked.join(a.inputs, b.inputs), Stacked.join(a.targets, b.targets),
                   Stacked.join(a.valid, b.valid), np.concatenate([a.scale, b.scale]), list(a.names) + list(b.names),
                   join(a.unbiased, b.unbiased), has, join(a.links, b.links))


def encode_scene(path: str, resolution: int, voxels: int = ENCODING_VOXELS) -> dict[str, np.ndarray]:
    from viewer.training.dataset import load_example

    example = load_example(path)
    grid = voxelize(example.scene, voxels)
    enc = encoding.encode(grid, example.scene.sun, example.lo, example.hi, resolution,
                          encoding.occluders(example.scene, grid), encoding.DIRECT_SHADOWS)
    valid = example.valid[resolution]
    # the light reflected by surfaces: all of it minus the part straight from emitters and the sun,
    # filled inside solid objects like the total
    reflected = fill_invalid(example.raw[resolution] - example.direct[resolution], valid)
    target = np.concatenate([example.targets[resolution], reflected], axis=3)  # (M, M, M, 18, 3), filled
    inv = np.where(enc.scale > 0, 1.0 / np.where(enc.scale > 0, enc.scale, 1.0), 0.0)

    def scaled(sh):  # (M, M, M, K, 3) -> (3, K, M, M, M) / scale
        return (sh.transpose(4, 3, 0, 1, 2) * inv[:, None, None, None, None]).astype(np.float16)

    has_unbiased = resolution in example.mitsuba
    unbiased = (fill_invalid(example.mitsuba[resolution] - example.mitsuba_direct[resolution], valid)
                if has_unbiased else np.zeros_like(reflected))
    return {"inputs": enc.inputs.astype(np.float16), "targets": scaled(target), "unbiased": scaled(unbiased),
            "has_unbiased": np.array(has_unbiased), "valid": valid, "scale": enc.scale,
            "links": np.ones((3,) + valid.shape, bool) if enc.links is None else enc.links,
            "names": np.array(room_of(path))}


def room_of(ref: str) -> str:
    """The room's name from its reference: `shard.zip#room`, or a one-room file's stem (format 1)."""
    path, _, room = str(ref).partition("#")
    return room or Path(path).stem


def split_files(root: Path, split: str) -> list[str]:
    """The split's rooms as `dataset.room_refs` lists them (one-room files, or rooms in shards)."""
    from viewer.training.dataset import room_refs

    return room_refs(root, split)


def load_split(root: Path, split: str, resolution: int, workers: int = 2, quiet: bool = False,
               voxels: int = ENCODING_VOXELS, encode: bool = True, rooms: int = 0) -> Samples:
    """The encoded split, from the caches where they match the dataset's files, else encoded now (or,
    with `encode=False`, left out: training on the shards encoded so far while a dataset grows).
    `rooms`: only the shards that hold the split's first so many rooms (0: all)."""
    arrays = encoded_split(root, split, "probenet", partial(encode_scene, voxels=voxels), resolution, workers,
                           quiet, key_extra=voxels, encode=encode, rooms=rooms)
    return Samples(arrays["inputs"], arrays["targets"], arrays["valid"], np.asarray(arrays["scale"]),
                   [str(n) for n in arrays["names"]], arrays["unbiased"], np.asarray(arrays["has_unbiased"], bool),
                   arrays.get("links"))


def containers(root: Path, split: str) -> dict[str, list[str]]:
    """{container: its rooms' refs}: a shard per container, and the one-room files of format 1 together."""
    out: dict[str, list[str]] = {}
    for ref in split_files(root, split):
        path, _, room = ref.partition("#")
        out.setdefault(path if room else "rooms", []).append(ref)
    return out


def encoded_split(root: Path, split: str, tag: str, encoder, resolution: int, workers: int = 2,
                  quiet: bool = False, key_extra=None, encode: bool = True, rooms: int = 0) -> dict[str, Stacked]:
    """{name: rows of every container} of `encoder(ref, resolution)` -> dict over a split's rooms, cached
    per container (shard) in `<root>/cache/<split>/` under a key of its rooms and their files' sizes, the
    encoder's tag, CACHE_VERSION and the encoding's version and `SETTINGS`, and read back memory-mapped.
    `rooms`: only the containers that hold the first so many rooms (0: all), so that a run on part of a
    dataset encodes no more than it reads."""
    groups = containers(root, split)
    if not groups:
        raise FileNotFoundError(f"no scenes in {Path(root) / split}")
    if rooms:
        kept, held = {}, 0
        for name, refs in groups.items():
            if held >= rooms:
                break
            kept[name], held = refs, held + len(refs)
        groups = kept
    parts = [_cached(Path(root), split, name, refs, tag, encoder, resolution, workers, quiet, key_extra, encode)
             for name, refs in groups.items()]
    parts = [p for p in parts if p is not None]
    if not parts:
        raise FileNotFoundError(f"no encoded rooms of {Path(root) / split} yet")
    return {name: Stacked([p[name] for p in parts]) for name in parts[0]}


def _cached(root: Path, split: str, container: str, refs: list[str], tag: str, encoder, resolution: int,
            workers: int, quiet: bool, key_extra, encode: bool = True) -> dict[str, np.ndarray] | None:
    files = sorted({ref.partition("#")[0] for ref in refs})
    rooms = [(room_of(ref), Path(ref.partition("#")[0]).stat().st_size) for ref in refs]
    key = hashlib.sha1(json.dumps([CACHE_VERSION, encoding.VERSION, list(encoding.FEATURES), encoding.SETTINGS,
                                   tag, key_extra,
                                   resolution, rooms, [Path(f).name for f in files]]).encode()).hexdigest()[:12]
    folder = root / "cache" / split / f"{Path(container).stem}-{tag}-m{resolution}-{key}"
    if not (folder / "done").exists():
        if not encode:
            return None
        _encode_to(folder, split, container, refs, encoder, resolution, workers, quiet)
    return {p.stem: np.load(p, mmap_mode="r") for p in sorted(folder.glob("*.npy"))}


def _encode_to(folder: Path, split: str, container: str, refs: list[str], encoder, resolution: int,
               workers: int, quiet: bool) -> None:
    label = f"{split}/{Path(container).stem}"
    for stale in folder.parent.glob(f"{folder.name}.*.tmp"):  # an encoder stopped half-way
        if not _alive(stale.name.split(".")[-2]):
            shutil.rmtree(stale, ignore_errors=True)
    tmp = folder.with_name(f"{folder.name}.{os.getpid()}.tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    arrays: dict[str, np.ndarray] = {}
    start = time.perf_counter()
    # spawned, not forked: the encoder's compiled loops may have started OpenMP threads in this process
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        for i, row in enumerate(pool.map(encoder, refs, [resolution] * len(refs), chunksize=2)):
            if not arrays:  # one memory-mapped file per array, filled row by row
                arrays = {name: np.lib.format.open_memmap(tmp / f"{name}.npy", "w+", _stored(value),
                                                          (len(refs),) + np.shape(value))
                          for name, value in row.items()}
            for name, value in row.items():
                arrays[name][i] = value
            if not quiet and ((i + 1) % 20 == 0 or i + 1 == len(refs)):
                rate = (i + 1) / (time.perf_counter() - start)
                print(f"\rencoding {label}: {i + 1}/{len(refs)} ({rate:.1f} rooms/s)", end="", file=sys.stderr)
    if not quiet:
        print(file=sys.stderr)
    for value in arrays.values():
        value.flush()
    del arrays
    (tmp / "done").write_text("")
    shutil.rmtree(folder, ignore_errors=True)
    tmp.replace(folder)


def _alive(pid: str) -> bool:
    try:
        os.kill(int(pid), 0)
    except (ValueError, ProcessLookupError):
        return False
    except PermissionError:
        return True
    return True


def _stored(value) -> np.dtype:
    """The dtype a cache keeps a value in: names get room for any room's name."""
    dtype = np.asarray(value).dtype
    return np.dtype("<U64") if dtype.kind == "U" else dtype


def main(argv=None) -> int:
    from viewer.cli_parsing import add_data, tool_parser

    parser = tool_parser(__doc__, prog="python -m viewer.training.samples")
    add_data(parser)
    parser.add_argument("--probes", type=int, default=24)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--splits", default="paper,val,train")
    args = parser.parse_args(argv)
    for split in args.splits.split(","):
        samples = load_split(args.data, split, args.probes, workers=args.workers)
        print(f"{split}: {len(samples)} rooms, inputs {samples.inputs.shape}, "
              f"{int(np.sum(samples.has_unbiased))} with Mitsuba's probes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
