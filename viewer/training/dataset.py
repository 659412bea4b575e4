"""The neural GI model's dataset: procedural rooms with their ground-truth probe SH, in shards.

    python -m viewer.training.dataset --out data/gi-v2 --train 5000 --val 300 --seed 14 --probes 24,16

The rooms are made in parallel on Ray (viewer.training.generate: `ray.init()` on this machine, or
`--address` to join a cluster); this module is the format and how to read it back, and
viewer/training/dataset_cli.py the command line.

Layout under --out (format 2):
    manifest.json             the command, settings, versions, counts, shards, seconds per room, rooms/hour
    paper/shard-00000.zip     the fixed scenes paper-train-1..5, paper-test, cornell (made first)
    val/shard-NNNNN.zip       validation rooms (made second), `--shard-size` rooms a shard
    train/shard-NNNNN.zip     training rooms
A shard is a zip archive (stored, not compressed again) of one `.npz` per room, named after the room
(`train-00012.npz`), and `shard.json` (the settings and the rooms it holds). An unfinished shard's rooms
wait in `<split>/pending/` until the shard is packed, so an interrupted run loses no finished room.
Format 1 (one `.npz` per room straight under `<split>/`, the first dataset gi-v1) is still read.

Room i of a procedural split comes from `np.random.default_rng([seed, split_id, i])` (train 0, val 1)
with the ranges preset the manifest names (viewer.neural.ranges), so any room can be made again alone.
Keys of one room's `.npz` (`FORMAT` below):
    name, params, generator   JSON strings: scene name, the drawn parameters, how the room was made
    vertices (V, 3) float32, faces (F, 3) int32, albedo (F, 3) float16, emission (F, 3) float32,
    face_group (F,) int16, groups (JSON list of names), sun (6,) float64 direction + irradiance or (0,),
    camera (10,) float64 origin, target, up, fov
    lo, hi (3,) float64      the probe box: scene.bounds, as `viewer.physical.gi.solve` uses
    sh_{M} (M, M, M, 9, 3)   ground-truth incident-radiance SH at the probe centres (format 2: float16,
                             relative precision 5e-4, or float32 where a value is past float16's range)
    sh_{M}_direct            the part of sh_{M} straight from emitters and the sun (sh_{M} - sh_{M}_direct
                             is the reflected light the renderer's probes hold: it shades emitters and the
                             sun itself)
    sh_{M}_filled            format 1 only: sh_{M} with invalid probes filled (format 2 fills on loading,
                             `probes.fill_invalid`, the rule the renderer and the physical solver use)
    sh_{M}_mitsuba, sh_{M}_mitsuba_direct
                             with --mitsuba-directions, at the finest M only, in the rooms --mitsuba-every
                             picks: Mitsuba's probes at that many directions beside the physical solver's
                             (noisy, unbiased; float16)
    valid_{M} (M, M, M) bool False for probes inside solid objects
    seconds () float64       time spent making the room
The scene is stored exactly as the truth saw it (rounded to the stored precisions first).
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import zipfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterator

import numpy as np

from viewer.probes.grid import fill_invalid
from viewer.scene import Camera, DirectionalLight, Scene, load
from viewer.evaluation import procedural
from viewer.training import truth as truths
from viewer.neural.ranges import PRESETS

FORMAT = 2
"""2: rooms in shards, targets float16, filled on loading. 1: one file per room (read, no longer made)."""
SPLITS = ("paper", "val", "train")
"""In the order they are made: the fixed scenes first, so that training can start on them."""
SPLIT_IDS = {"train": 0, "val": 1, "paper": 2}
PAPER_SCENES = ("paper-train-1", "paper-train-2", "paper-train-3", "paper-train-4", "paper-train-5",
                "paper-test", "cornell")
SHARD_GLOB = "shard-*.zip"
FLOAT16_LIMIT = 60000.0
"""Targets are stored as float16 while every value stays below this (float16's largest is 65504)."""


# ---- one example ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Example:
    path: Path
    """The room's file: a one-room `.npz`, or the shard holding it (then `name` says which room)."""
    scene: Scene
    lo: np.ndarray
    """(3,) lower corner of the probe box (scene.bounds)."""
    hi: np.ndarray
    targets: dict[int, np.ndarray]
    """{M: (M, M, M, 9, 3) float32} ground-truth SH with invalid probes filled from valid neighbours
    (what the renderer samples); `raw` has them as traced."""
    raw: dict[int, np.ndarray]
    direct: dict[int, np.ndarray]
    """{M: (M, M, M, 9, 3) float32} the part of `raw` straight from the emitters and the sun."""
    valid: dict[int, np.ndarray]
    """{M: (M, M, M) bool} False inside solid objects."""
    params: dict
    generator: dict
    mitsuba: dict[int, np.ndarray] = field(default_factory=dict)
    """{M: (M, M, M, 9, 3) float32} Mitsuba's probes at few directions, filled like `targets`, where the
    dataset has them beside another truth (`--mitsuba-directions`): noisy, unbiased."""
    mitsuba_direct: dict[int, np.ndarray] = field(default_factory=dict)
    """{M: ...} their part straight from the emitters and the sun (raw)."""

    @property
    def name(self) -> str:
        return self.scene.name


def quantized(scene: Scene) -> Scene:
    """The scene at the precisions the file stores, so that the stored scene is the one the truth saw."""
    return replace(scene, vertices=scene.vertices.astype(np.float32).astype(np.float64),
                   albedo=scene.albedo.astype(np.float16).astype(np.float64),
                   emission=scene.emission.astype(np.float32).astype(np.float64))


def scene_arrays(scene: Scene) -> dict[str, np.ndarray]:
    sun = (np.concatenate([scene.sun.direction, scene.sun.irradiance]) if scene.sun is not None
           else np.zeros(0))
    c = scene.camera
    return {"name": np.array(scene.name), "vertices": scene.vertices.astype(np.float32),
            "faces": scene.faces.astype(np.int32), "albedo": scene.albedo.astype(np.float16),
            "emission": scene.emission.astype(np.float32), "face_group": scene.face_group.astype(np.int16),
            "groups": np.array(json.dumps(list(scene.groups))), "sun": sun.astype(np.float64),
            "camera": np.array([*c.origin, *c.target, *c.up, c.fov], np.float64)}


def scene_from_arrays(data) -> Scene:
    sun = np.asarray(data["sun"], np.float64)
    c = np.asarray(data["camera"], np.float64)
    return Scene(name=str(data["name"]), vertices=data["vertices"], faces=data["faces"],
                 albedo=data["albedo"], emission=data["emission"], face_group=data["face_group"],
                 groups=tuple(json.loads(str(data["groups"]))),
                 sun=DirectionalLight(sun[:3], sun[3:]) if len(sun) else None,
                 camera=Camera(tuple(c[0:3]), tuple(c[3:6]), tuple(c[6:9]), float(c[9])))


def target_arrays(targets: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """`truth.targets`' arrays as format 2 stores them: no filled copy, SH as float16 where they fit."""
    out = {}
    for key, value in targets.items():
        if key.endswith("_filled"):
            continue
        if key.startswith("sh_") and np.all(np.abs(value) < FLOAT16_LIMIT):
            value = value.astype(np.float16)
        out[key] = value
    return out


def room_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """One room as the bytes of a compressed `.npz`."""
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    return buffer.getvalue()


def example_from(data, path: Path) -> Example:
    """An Example from an open `.npz` of either format, with the coarser lattices its stored ones contain
    (`coarser_lattices`)."""
    resolutions = sorted(int(k[3:]) for k in data.files if k.startswith("sh_") and k[3:].isdigit())
    raw = {m: np.asarray(data[f"sh_{m}"], np.float32) for m in resolutions}
    valid = {m: np.asarray(data[f"valid_{m}"], bool) for m in resolutions}
    direct = {m: np.asarray(data[f"sh_{m}_direct"], np.float32) for m in resolutions}
    unbiased = [m for m in resolutions if f"sh_{m}_mitsuba" in data.files]
    mitsuba = {m: np.asarray(data[f"sh_{m}_mitsuba"], np.float32) for m in unbiased}
    mitsuba_direct = {m: np.asarray(data[f"sh_{m}_mitsuba_direct"], np.float32) for m in unbiased}
    stored = {m: (np.asarray(data[f"sh_{m}_filled"], np.float32) if f"sh_{m}_filled" in data.files else None)
              for m in resolutions}
    for fine, (m, pick) in [(r, c) for r in resolutions for c in coarser_lattices(r)]:
        if m in raw:
            continue
        for arrays in (raw, valid, direct) + ((mitsuba, mitsuba_direct) if fine in mitsuba else ()):
            arrays[m] = arrays[fine][pick, pick, pick]
        stored[m] = None
    filled = {m: stored[m] if stored[m] is not None else fill_invalid(raw[m], valid[m]) for m in raw}
    return Example(path=path, scene=scene_from_arrays(data), lo=data["lo"], hi=data["hi"], targets=filled,
                   raw=raw, direct=direct, valid=valid, params=json.loads(str(data["params"])),
                   generator=json.loads(str(data["generator"])),
                   mitsuba={m: fill_invalid(v, valid[m]) for m, v in mitsuba.items()}, mitsuba_direct=mitsuba_direct)


def coarser_lattices(resolution: int) -> list[tuple[int, slice]]:
    """[(m, slice)] for the lattices of m^3 cells over the same box whose probes are probes of the
    `resolution`^3 one: the probes sit at cell centres, so where `resolution` = k m with k odd, the centre
    of coarse cell j is the centre of fine cell k j + (k - 1) / 2 (the 8^3 probes of a 24^3 room are its
    probes 1, 4, ..., 22 along each axis). Lattices under 4^3 are left out."""
    return [(resolution // k, slice((k - 1) // 2, None, k)) for k in range(3, resolution // 4 + 1, 2)
            if resolution % k == 0]


def load_example(ref, room: str | None = None) -> Example:
    """One room: `ref` a one-room `.npz` (format 1), or a shard with `room` (or `"shard.zip#room"`, the
    form `room_refs` lists)."""
    path, _, name = str(ref).partition("#")
    path, room = Path(path), room or name or None
    if room is None:
        with np.load(path) as data:
            return example_from(data, path)
    with zipfile.ZipFile(path) as archive:
        payload = archive.read(f"{room}.npz")
    with np.load(io.BytesIO(payload)) as data:
        return example_from(data, path)


def shard_rooms(path: Path) -> list[str]:
    """The rooms a shard holds, in order (from its shard.json)."""
    with zipfile.ZipFile(path) as archive:
        return list(json.loads(archive.read("shard.json"))["rooms"])


def room_refs(root, split: str) -> list[str]:
    """Every room of a split, in order: `path` for a format-1 file, `shard.zip#room` for a room in a shard."""
    folder = Path(root) / split
    refs = [str(p) for p in sorted(folder.glob("*.npz"))]
    for shard in sorted(folder.glob(SHARD_GLOB)):
        refs += [f"{shard}#{room}" for room in shard_rooms(shard)]
    return refs


def iter_split(root, split: str) -> Iterator[Example]:
    """The examples of one split (`train`, `val` or `paper`), in order."""
    for ref in room_refs(root, split):
        yield load_example(ref)


def make_scene(split: str, index: int, seed: int, ranges: str = "v1") -> tuple[Scene, dict]:
    """Room `index` of `split` (a fixed scene for `paper`), as the dataset stores it."""
    if split == "paper":
        scene = load(PAPER_SCENES[index])
        return quantized(scene), {"source": "builtin", "name": scene.name}
    rng = np.random.default_rng([seed, SPLIT_IDS[split], index])
    scene, params = procedural.random_scene(rng, f"{split}-{index:05d}", PRESETS[ranges])
    return quantized(scene), params


def room_name(split: str, index: int) -> str:
    return PAPER_SCENES[index] if split == "paper" else f"{split}-{index:05d}"


# ---- command line --------------------------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    from viewer.cli_parsing import tool_parser

    p = tool_parser(
        prog="python -m viewer.training.dataset",
        description="Generate the neural GI dataset in parallel on Ray: procedural rooms (train/, val/) and "
                    "the fixed paper scenes (paper/), each with ground-truth probe SH over scene.bounds, in "
                    "shards of --shard-size rooms plus manifest.json. Resumable: run the same command again "
                    "and finished rooms are kept (checked), missing ones made. Order: paper, val, train.",
        epilog="example: python -m viewer.training.dataset --out data/gi-v2 --train 5000 --val 300 --seed 14 "
               "--probes 24,16")
    p.add_argument("--out", type=Path, help="dataset folder (created; holds manifest.json and the splits)")
    p.add_argument("--train", type=int, default=5000, help="procedural training rooms (default 5000)")
    p.add_argument("--val", type=int, default=300, help="procedural validation rooms (default 300)")
    p.add_argument("--seed", type=int, default=14, help="room i of a split is default_rng([seed, split, i])")
    p.add_argument("--ranges", choices=sorted(PRESETS), default="v2",
                   help="procedural ranges (viewer.neural.ranges; default v2, the wide ones)")
    p.add_argument("--probes", default="24,16", help="probe resolutions M, comma separated (default 24,16)")
    p.add_argument("--truth", choices=truths.TRUTHS, default="physical",
                   help="ground truth: physical (viewer.physical.gi's solver, ~1-3 s a room; the default, "
                        "docs/TRAINING.md says why), mitsuba (path traced, --directions stratified rays with "
                        "light sampling per probe) or solver (the all-pairs numpy solver, slow)")
    p.add_argument("--directions", type=int, default=256,
                   help="directions per probe (physical: the probe projection's; mitsuba: rays)")
    p.add_argument("--voxels", type=int, default=32, help="voxels per axis of the solvers (default 32)")
    p.add_argument("--mitsuba-directions", type=int, default=0,
                   help="also store Mitsuba's probes at this many directions at the finest --probes beside "
                        "the physical truth (an unbiased, noisy second target; 0: none, the default)")
    p.add_argument("--mitsuba-every", type=int, default=1,
                   help="with --mitsuba-directions: every val and paper room, and the train rooms whose index "
                        "is a multiple of this (default 1: all)")
    p.add_argument("--splits", default=",".join(SPLITS),
                   help=f"splits to make, comma separated (default {','.join(SPLITS)}, in that order)")
    p.add_argument("--shard-size", type=int, default=200, help="rooms per shard (default 200)")
    p.add_argument("--workers", type=int, default=None,
                   help="CPUs to use on this machine (default: every core); with --address, at most this "
                        "many rooms at once")
    p.add_argument("--address", default=None,
                   help="join an existing Ray cluster (e.g. auto, or ray://host:10001) instead of starting "
                        "one here")
    p.add_argument("--verify", action="store_true",
                   help="check every room of every finished shard in full (shapes, finite values) before "
                        "resuming, not only the shard's size, index and CRCs")
    p.add_argument("--dump-obj", type=Path, metavar="DIR",
                   help="instead of generating: write the scenes --indices of --split as OBJ+MTL+JSON "
                        "into DIR (for `python -m viewer capture DIR/NAME.obj`)")
    p.add_argument("--split", choices=SPLITS, default="train", help="split for --dump-obj")
    p.add_argument("--indices", default="0,1,2,3", help="scene indices for --dump-obj, comma separated")
    return p


if __name__ == "__main__":  # the documented command, `python -m viewer.training.dataset`
    from viewer.training.dataset_cli import main

    sys.exit(main())
