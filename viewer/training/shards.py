"""The dataset on disk: its settings, shards, pending rooms and the manifest (format 2).

A shard is a zip archive (stored, not compressed again) of one `.npz` per room plus `shard.json` (the
settings and the rooms it holds, and any room that failed, with why). Rooms wait in `<split>/pending/`
until the last room of their shard is in, then `pack` writes the shard through a temporary file and
removes them. viewer.training.generate makes the rooms; viewer.training.dataset reads them back.
"""

from __future__ import annotations

import io
import json
import os
import platform
import subprocess
import time
import zipfile
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from viewer.scene import SceneError
from viewer.scene.files import check_readable
from viewer.training import dataset
from viewer.neural.ranges import PRESETS

FINGERPRINT = ("format", "seed", "ranges", "truth", "directions", "probes", "voxels", "mitsuba_directions",
               "mitsuba_every", "shard_size")
"""The settings a resumed run must share with the dataset it continues."""


@dataclass(frozen=True)
class Settings:
    seed: int = 14
    """Room i of a split is drawn from np.random.default_rng([seed, split id, i])."""
    ranges: str = "v2"
    """Name of the procedural ranges preset (viewer.neural.ranges.PRESETS)."""
    truth: str = "physical"
    """Ground truth of the targets: physical, mitsuba or solver (viewer.training.truth)."""
    directions: int = 256
    """Directions per probe of the truth."""
    probes: tuple[int, ...] = (24, 16)
    """Probe resolutions M of the targets."""
    voxels: int = 32
    """Voxels per axis of the solvers (physical, solver)."""
    mitsuba_directions: int = 0
    """With another truth: Mitsuba's probes at this many directions too, at the finest resolution
    (`sh_{M}_mitsuba`, `sh_{M}_mitsuba_direct`): an unbiased, noisy second target. 0: none."""
    mitsuba_every: int = 1
    """Which rooms get that second target: every validation and paper room, and the training rooms whose
    index is a multiple of this."""
    counts: dict = field(default_factory=lambda: {"paper": len(dataset.PAPER_SCENES), "val": 300, "train": 5000})
    """Rooms per split."""
    shard_size: int = 200
    """Rooms per shard."""

    def fingerprint(self) -> dict:
        return {"format": dataset.FORMAT, **{k: v for k, v in asdict(self).items() if k in FINGERPRINT},
                "probes": list(self.probes)}

    def unbiased(self, split: str, index: int) -> bool:
        """Whether this room gets Mitsuba's probes beside the truth's."""
        return self.mitsuba_directions > 0 and (split != "train" or index % self.mitsuba_every == 0)

    def generator(self, split: str, index: int) -> dict:
        """What one room records of how it was made."""
        return {**self.fingerprint(), "split": split, "index": index}


def room_ok(payload: bytes, generator: dict, probes) -> bool:
    """Whether a room's .npz reads back whole (CRCs), was made with `generator` and holds finite targets
    of the right shapes."""
    try:
        with np.load(io.BytesIO(payload)) as data:
            if json.loads(str(data["generator"])) != generator:
                return False
            for m in probes:
                for key, shape in ((f"sh_{m}", (m, m, m, 9, 3)), (f"sh_{m}_direct", (m, m, m, 9, 3)),
                                   (f"valid_{m}", (m, m, m))):
                    if data[key].shape != shape or not np.all(np.isfinite(data[key])):
                        return False
            dataset.scene_from_arrays(data)
    except Exception:  # noqa: BLE001 - truncated, corrupt, old or foreign: make it again
        return False
    return True


# ---- shards --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Shard:
    split: str
    number: int
    indices: tuple[int, ...]

    @property
    def name(self) -> str:
        return f"shard-{self.number:05d}.zip"

    def rooms(self) -> list[str]:
        return [dataset.room_name(self.split, i) for i in self.indices]


def plan(settings: Settings, splits) -> list[Shard]:
    shards = []
    for split in [s for s in dataset.SPLITS if s in splits]:
        count, size = settings.counts[split], settings.shard_size
        for number, start in enumerate(range(0, count, size)):
            shards.append(Shard(split, number, tuple(range(start, min(start + size, count)))))
    return shards


def shard_ok(path: Path, shard: Shard, settings: Settings, recorded: dict | None, verify: bool) -> bool:
    """The check every resume makes (zip index, shard.json, recorded size, and each member's CRC-32, which
    reads the shard once at disk speed: a flipped bit is found now, not when training reads the room)
    and with `verify` every room in full (shapes, finite values, the room's own settings)."""
    if not path.exists() or (recorded is not None and recorded.get("bytes") != path.stat().st_size):
        return False
    try:
        with zipfile.ZipFile(path) as archive:
            index = json.loads(archive.read("shard.json"))
            rooms = shard.rooms()
            failed = [name for name, _ in index.get("failed", [])]
            if index.get("settings") != settings.fingerprint() or sorted(index["rooms"] + failed) != sorted(rooms):
                return False
            if not set(f"{r}.npz" for r in index["rooms"]) <= set(archive.namelist()):
                return False
            if archive.testzip() is not None:
                return False
            if verify:
                for room, i in zip(rooms, shard.indices):
                    if room in index["rooms"] and not room_ok(archive.read(f"{room}.npz"),
                                                              settings.generator(shard.split, i), settings.probes):
                        return False
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return False
    return True


def pack(folder: Path, shard: Shard, settings: Settings, failed: dict[str, str]) -> dict:
    """The shard from its pending rooms (stored: the rooms are compressed already), written through a
    temporary file; the pending rooms are removed after. Returns its manifest record."""
    pending = folder / "pending"
    made = [r for r in shard.rooms() if r not in failed]
    path = folder / shard.name
    tmp = path.with_name(path.name + ".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED) as archive:
        for room in made:
            archive.write(pending / f"{room}.npz", f"{room}.npz")
        archive.writestr("shard.json", json.dumps({"settings": settings.fingerprint(), "rooms": made,
                                                   "failed": [[r, failed[r]] for r in shard.rooms() if r in failed]}))
    with open(tmp, "rb") as fh:
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    for room in made:
        (pending / f"{room}.npz").unlink(missing_ok=True)
    if pending.is_dir() and not any(pending.iterdir()):
        pending.rmdir()
    return {"rooms": len(made), "failed": len(shard.rooms()) - len(made), "bytes": path.stat().st_size}


def write_pending(folder: Path, room: str, payload: bytes) -> None:
    pending = folder / "pending"
    pending.mkdir(parents=True, exist_ok=True)
    tmp = pending / f"{room}.npz.tmp"
    tmp.write_bytes(payload)
    os.replace(tmp, pending / f"{room}.npz")


# ---- the manifest ---------------------------------------------------------------------------------------

MANIFEST_BYTES = 64 << 20
"""The largest manifest.json read (64 MiB: a few hundred bytes a shard)."""
MANIFEST_PARTS = {"settings": dict, "splits": dict, "failed": dict, "commands": list, "timing": dict}
"""The manifest's entries a resumed run reads, and what each must be."""


def read_manifest(path: Path) -> dict:
    """An existing manifest.json as the dict it must be; a directory, a pipe, bad JSON, a list or an entry
    of the wrong kind is a SceneError in one line (the dataset command: exit status 2)."""
    check_readable(path, "manifest", limit=MANIFEST_BYTES)
    try:
        data = json.loads(path.read_text())
    except (ValueError, RecursionError) as exc:   # bad JSON, bytes that are not UTF-8, nested too deep
        raise SceneError(f"{path}: not a readable manifest ({type(exc).__name__}); use another --out, or "
                         "remove it to start again") from None
    if not isinstance(data, dict):
        raise SceneError(f"{path}: a manifest is a JSON object, this is a {type(data).__name__}")
    for key, kind in MANIFEST_PARTS.items():
        if key in data and not isinstance(data[key], kind):
            raise SceneError(f"{path}: its {key!r} is a {type(data[key]).__name__}, not a {kind.__name__}")
    timing = data.get("timing", {})
    if not all(isinstance(timing.get(k, 0), (int, float)) for k in ("rooms_made", "worker_seconds", "wall_seconds")):
        raise SceneError(f"{path}: its 'timing' holds something other than numbers")
    for split in data.get("splits", {}).values():
        if not isinstance(split, dict) or not isinstance(split.get("shards", {}), dict):
            raise SceneError(f"{path}: its 'splits' are not objects of shards")
    return data


class Manifest:
    """manifest.json: what the dataset is and how far it got, rewritten as shards land."""

    def __init__(self, out: Path, settings: Settings, command: str):
        self.path = out / "manifest.json"
        old = read_manifest(self.path) if self.path.exists() or self.path.is_symlink() else None
        if old is not None and old.get("settings") != settings.fingerprint():
            theirs = old.get("settings") or {k: old.get(k) for k in FINGERPRINT}
            differ = ", ".join(f"{k} {theirs.get(k)} != {v}" for k, v in settings.fingerprint().items()
                               if theirs.get(k) != v)
            raise SceneError(f"{self.path.parent} holds a dataset made with other settings ({differ}): "
                             "use another --out, or the same settings to resume")
        old = old or {}
        self.data = {"format": dataset.FORMAT, "settings": settings.fingerprint(),
                     "ranges": PRESETS[settings.ranges].as_dict(), "counts": dict(settings.counts),
                     "command": command, "commands": old.get("commands", []) + [command],
                     "versions": versions(settings.truth == "mitsuba" or settings.mitsuba_directions > 0),
                     "splits": old.get("splits", {}), "failed": old.get("failed", {}),
                     "started": old.get("started") or _now()}
        self.before = {"rooms_made": 0, "worker_seconds": 0.0, "wall_seconds": 0.0, **old.get("timing", {})}
        """The timing of earlier runs; `save` adds this run's."""

    def shards(self, split: str) -> dict:
        return self.data["splits"].setdefault(split, {}).setdefault("shards", {})

    def record(self, shard: Shard, entry: dict | None) -> None:
        shards = self.shards(shard.split)
        if entry is None:
            shards.pop(shard.name, None)
        else:
            shards[shard.name] = entry

    def save(self, settings: Settings, made: int, worker_seconds: float, wall_seconds: float, workers: int) -> None:
        """Write it, with this run's rooms made, their seconds in the workers and its wall-clock seconds
        so far added to the earlier runs'."""
        timing = {"rooms_made": self.before["rooms_made"] + made,
                  "worker_seconds": self.before["worker_seconds"] + worker_seconds,
                  "wall_seconds": self.before["wall_seconds"] + wall_seconds}
        if timing["rooms_made"]:
            timing["seconds_per_room"] = timing["worker_seconds"] / timing["rooms_made"]
            timing["rooms_per_hour"] = 3600.0 * timing["rooms_made"] / max(timing["wall_seconds"], 1e-9)
        timing["workers"] = workers
        for split, count in settings.counts.items():
            entry = self.data["splits"].setdefault(split, {})
            entry["shards"] = dict(sorted(entry.get("shards", {}).items()))
            entry["count"] = count
            entry["done"] = sum(s["rooms"] + s.get("failed", 0) for s in entry.get("shards", {}).values())
        data = {**self.data, "timing": timing, "updated": _now()}
        tmp = self.path.with_name("manifest.json.tmp")
        tmp.write_text(json.dumps(data, indent=1) + "\n")
        os.replace(tmp, self.path)


def versions(mitsuba: bool) -> dict:
    out = {"python": platform.python_version(), "numpy": np.__version__}
    for package in ("gi-viewer", "numba", "ray"):
        try:
            from importlib.metadata import version

            out[package] = version(package)
        except Exception:  # noqa: BLE001
            pass
    if mitsuba:
        import drjit
        import mitsuba

        from viewer.reference import mitsuba as reference

        out.update(mitsuba=mitsuba.__version__, drjit=drjit.__version__, variant=reference.variant())
    try:
        out["commit"] = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                                       cwd=Path(__file__).parent, timeout=10).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        pass
    return out


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


