"""Dataset scenes -> training tensors for ProbeNet: encoded inputs and scaled targets, cached per split.

    python -m viewer.training.samples --data data/gi-v1 [--probes 16]   # builds the caches (optional:
                                                                          # training builds them too)

A scene's inputs come from `viewer.encoding.encode` on its voxels (the same call the viewer makes); its
target is the filled ground-truth SH of the dataset (`sh_{M}_filled`), per colour channel, divided by
the encoding's scale, so that inputs and targets are in the same units. Encoding a scene means
voxelizing it (about 0.3 s at 32^3), so every split is encoded once, by a pool of processes, and kept in
`<data>/cache/`.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from viewer import encoding
from viewer.probes import fill_invalid
from viewer.voxels import voxelize

ENCODING_VOXELS = 16
"""Voxel resolution the encoder reads, recorded in the model card. 16: the lattice it is gathered onto is
16^3 too, and voxelizing at 16^3 takes a quarter of the time of 32^3 (an edit in the viewer waits for it)."""
CACHE_VERSION = 3
"""Bump when `encoding` changes, so that stale caches are rebuilt."""


@dataclass
class Samples:
    inputs: np.ndarray
    """(S, 3, CHANNELS, M, M, M) float16: scene s, colour channel c."""
    targets: np.ndarray
    """(S, 3, 18, M, M, M) float32: ground-truth SH / scale: all the incident light (9), then the light
    reflected by surfaces alone (9)."""
    valid: np.ndarray
    """(S, M, M, M) bool."""
    scale: np.ndarray
    """(S, 3) float32."""
    names: list[str]

    def __len__(self) -> int:
        return len(self.names)

    def physical(self, normalized: np.ndarray) -> np.ndarray:
        """(S, 3, K, M, M, M) scaled SH -> (S, M, M, M, K, 3) in radiance units."""
        return (normalized * self.scale[:, :, None, None, None, None]).transpose(0, 3, 4, 5, 2, 1)


PAPER_TRAINING = ("paper-train-1", "paper-train-2", "paper-train-3", "paper-train-4", "paper-train-5")
"""The paper's five training layouts join the procedural rooms in training; `paper-test` (held out) and
`cornell` (paper-test without its new sphere and pink wall) never do."""


def training_split(root: Path, resolution: int, quiet: bool = False) -> "Samples":
    """The procedural `train` split plus the paper's training layouts."""
    train = load_split(root, "train", resolution, quiet=quiet)
    paper = load_split(root, "paper", resolution, quiet=quiet)
    return concat(train, paper, keep=[n for n in paper.names if n in PAPER_TRAINING])


def concat(a: "Samples", b: "Samples", keep=None) -> "Samples":
    """a followed by b's scenes named in `keep` (all of b by default)."""
    index = [i for i, n in enumerate(b.names) if keep is None or n in keep]
    return Samples(np.concatenate([a.inputs, b.inputs[index]]), np.concatenate([a.targets, b.targets[index]]),
                   np.concatenate([a.valid, b.valid[index]]), np.concatenate([a.scale, b.scale[index]]),
                   list(a.names) + [b.names[i] for i in index])


def encode_scene(path: str, resolution: int) -> dict[str, np.ndarray]:
    from viewer.training.dataset import load_example

    example = load_example(path)
    voxels = voxelize(example.scene, ENCODING_VOXELS)
    enc = encoding.encode(voxels, example.scene.sun, example.lo, example.hi, resolution)
    # the light reflected by surfaces: all of it minus the part straight from emitters and the sun,
    # filled inside solid objects like the total
    reflected = fill_invalid(example.raw[resolution] - example.direct[resolution], example.valid[resolution])
    target = np.concatenate([example.targets[resolution], reflected], axis=3)  # (M, M, M, 18, 3), filled
    inv = np.where(enc.scale > 0, 1.0 / np.where(enc.scale > 0, enc.scale, 1.0), 0.0)
    scaled = target.transpose(4, 3, 0, 1, 2) * inv[:, None, None, None, None]
    return {"inputs": enc.inputs.astype(np.float16), "targets": scaled.astype(np.float32),
            "valid": example.valid[resolution], "scale": enc.scale, "names": np.array(room_of(path))}


def room_of(ref: str) -> str:
    """The room's name from its reference: `shard.zip#room`, or a one-room file's stem (format 1)."""
    path, _, room = str(ref).partition("#")
    return room or Path(path).stem


def split_files(root: Path, split: str) -> list[str]:
    """The split's rooms as `dataset.room_refs` lists them (one-room files, or rooms in shards)."""
    from viewer.training.dataset import room_refs

    return room_refs(root, split)


def load_split(root: Path, split: str, resolution: int, workers: int = 2, quiet: bool = False) -> Samples:
    """The encoded split, from the cache when it matches the dataset's files, else encoded now."""
    arrays = encoded_split(root, split, "probenet", encode_scene, resolution, workers, quiet)
    return Samples(arrays["inputs"], arrays["targets"], arrays["valid"], arrays["scale"],
                   [str(n) for n in arrays["names"]])


def encoded_split(root: Path, split: str, tag: str, encoder, resolution: int, workers: int = 2,
                  quiet: bool = False) -> dict[str, np.ndarray]:
    """{name: stacked array} of `encoder(path, resolution)` -> dict over a split's files, cached in
    `<root>/cache/` under a key of the files, the encoder's tag and CACHE_VERSION."""
    files = split_files(root, split)
    if not files:
        raise FileNotFoundError(f"no scenes in {Path(root) / split}")
    sizes = {path: Path(path).stat().st_size for path in {ref.partition("#")[0] for ref in files}}
    rooms = [(room_of(f), sizes[f.partition("#")[0]]) for f in files]
    key = hashlib.sha1(json.dumps([CACHE_VERSION, encoding.VERSION, tag, ENCODING_VOXELS, resolution,
                                   rooms]).encode()).hexdigest()[:12]
    cache = Path(root) / "cache" / f"{split}-{tag}-m{resolution}-{key}.npz"
    if cache.exists():
        with np.load(cache) as z:
            return {name: z[name] for name in z.files}
    rows = []
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as pool:
        for i, row in enumerate(pool.map(encoder, files, [resolution] * len(files), chunksize=4)):
            rows.append(row)
            if not quiet and ((i + 1) % 20 == 0 or i + 1 == len(files)):
                rate = (i + 1) / (time.perf_counter() - start)
                print(f"\rencoding {split} ({tag}): {i + 1}/{len(files)} ({rate:.1f} scenes/s)", end="",
                      file=sys.stderr)
    if not quiet:
        print(file=sys.stderr)
    arrays = {name: np.stack([row[name] for row in rows]) for name in rows[0]}
    cache.parent.mkdir(parents=True, exist_ok=True)
    tmp = cache.with_suffix(f".{os.getpid()}.tmp.npz")
    np.savez(tmp, **arrays)
    tmp.replace(cache)
    return arrays


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m viewer.training.samples", description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path("data/gi-v1"))
    parser.add_argument("--probes", type=int, default=16)
    parser.add_argument("--splits", default="paper,val,train")
    args = parser.parse_args(argv)
    for split in args.splits.split(","):
        samples = load_split(args.data, split, args.probes)
        print(f"{split}: {len(samples)} scenes, inputs {samples.inputs.shape}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
