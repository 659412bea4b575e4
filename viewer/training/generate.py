"""Making the dataset on Ray: one task per room, shards, the manifest, resuming.

`python -m viewer.training.dataset` (the command, viewer/training/dataset_cli.py; viewer.training.dataset
is the format) calls `run`. Every room is a Ray task (`make_room`, one CPU: the solver's compiled loops
run single-threaded in it, so N workers keep N cores busy without oversubscribing them); the driver
writes each finished room to `<split>/pending/<room>.npz` at once and packs a shard when all of its rooms
are there. `ray.init()` starts Ray on this machine with every core (or `workers` of them); with
`address` it joins a cluster the user runs (the workers there must import the same `viewer` package).

Resuming: a packed shard is kept when its zip index lists exactly the rooms it should hold, its
shard.json was made with the same settings, its size is the one the manifest recorded and every
member's CRC-32 holds (`verify` also reads every room back: shapes, finite values); a pending room is kept when it reads back
whole. Settings that change what a room holds (seed, ranges, truth, directions, probes, voxels, shard
size) must match the manifest's; room counts may grow.
"""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from viewer.scene import SceneError
from viewer.training import dataset, truth as truths
from viewer.training.shards import Manifest, Settings, Shard, pack, plan, room_ok, shard_ok, write_pending


@dataclass
class Result:
    made: int
    skipped: int
    failed: list[str]
    elapsed: float
    """Wall-clock seconds of this run."""
    workers: int
    rooms_per_hour: float


# ---- one room (a Ray task) -----------------------------------------------------------------------------

def make_room(settings: Settings, split: str, index: int) -> tuple[str, bytes, float]:
    """(room name, the room's .npz bytes, seconds spent): deterministic for (settings, split, index)."""
    _one_thread(settings.truth == "mitsuba" or settings.unbiased(split, index))
    clock = time.perf_counter()
    scene, params = dataset.make_scene(split, index, settings.seed, settings.ranges)
    lo, hi = scene.bounds
    seed = int(np.random.default_rng([settings.seed, dataset.SPLIT_IDS[split], index, 0x7E]).integers(2**31))
    targets = truths.targets(scene, lo, hi, settings.probes, settings.truth, settings.directions, seed, None,
                             settings.voxels)
    if settings.unbiased(split, index):
        targets.update(truths.unbiased_targets(scene, lo, hi, max(settings.probes), settings.mitsuba_directions,
                                               seed))
    arrays = dataset.target_arrays(targets)
    seconds = time.perf_counter() - clock
    arrays.update(dataset.scene_arrays(scene))
    arrays.update(lo=np.asarray(lo, np.float64), hi=np.asarray(hi, np.float64),
                  params=np.array(json.dumps(params)),
                  generator=np.array(json.dumps(settings.generator(split, index))),
                  seconds=np.array(seconds, np.float64))
    return scene.name, dataset.room_bytes(arrays), seconds


def _one_thread(mitsuba: bool) -> None:
    """A task has one CPU: numba's (and Dr.Jit's) thread pools would otherwise take every core each."""
    import numba

    numba.set_num_threads(1)
    if mitsuba:
        import drjit

        drjit.set_thread_count(1)


# ---- the run -------------------------------------------------------------------------------------------

class Progress:
    """The run's counts (rooms made, worker seconds, wall clock) for the manifest, shown as a bar on stderr
    (viewer.progress.bar): rooms done of all, rooms per hour, seconds a room takes in a worker, time left.
    A failed room and a packed shard get lines of their own."""

    def __init__(self, total: int, done: int, stream=sys.stderr):
        self.total, self.done, self.stream = total, done, stream
        self.made, self.seconds = 0, 0.0
        self.start = time.perf_counter()
        self.bar = None   # shown once the workers are up: a run refused before that prints its error alone

    def show(self) -> None:
        from viewer.progress import bar

        self.bar = bar(self.total, "room", "rooms", done=self.done, stream=self.stream)

    def elapsed(self) -> float:
        return time.perf_counter() - self.start

    def rate(self) -> float:
        """Rooms per hour, wall clock, of this run."""
        elapsed = self.elapsed()
        return 3600.0 * self.made / elapsed if self.made and elapsed > 0 else 0.0

    def step(self, split: str, seconds: float, notes: list[str] = ()) -> None:
        self.made += 1
        self.seconds += seconds
        self.bar.set_postfix_str(f"{split}, {self.rate():.0f} rooms/h, {self.seconds / self.made:.2f} s/room "
                                 f"a worker", refresh=False)
        for note in notes:
            self.bar.write(note)
        self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


CONNECT_SECONDS = 10.0
"""How long `--address` may take to answer before the dataset command gives up on it."""
JOIN_TRIES = 3
"""How often Ray tries to reach the cluster's GCS at an address that answers: measured against a port that
accepts connections and says nothing, 3 tries gave up with a ConnectionError after 128 s (Ray's default
of 20 waits over 10 minutes)."""


def check_address(address: str, timeout: float = CONNECT_SECONDS) -> None:
    """SceneError in one line unless something listens at a `host:port` (or `ray://host:port`) address
    within `timeout` seconds: Ray itself retries a dead address for many minutes. `auto` and other forms
    are left to Ray."""
    import socket

    text = address.removeprefix("ray://")
    host, colon, port = text.rpartition(":")
    if not colon or not host:
        return
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise SceneError(f"--address {address!r}: expected host:port, e.g. 192.168.1.2:6379")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as exc:   # refused, unreachable, unknown host or timed out
        reason = (f"no answer within {timeout:g} s" if isinstance(exc, TimeoutError)
                  else exc.strerror or type(exc).__name__)
        raise SceneError(f"--address {address}: no Ray cluster answers there ({reason})") from None


def start_ray(workers: int | None, address: str | None) -> tuple[bool, int]:
    """Ray on this machine (every core, or `workers`) or the cluster at `address`, quiet (no dashboard,
    workers' output not forwarded). Returns (whether this call started it, CPUs to keep busy)."""
    import logging

    import ray

    started = not ray.is_initialized()
    if started:
        quiet = dict(include_dashboard=False, log_to_driver=False, logging_level=logging.ERROR)
        if address:
            check_address(address)
            # something answers, but it may not be Ray: a few tries of Ray's own connection timeout (about
            # 40 s each) instead of its default 20, unless the user set how long to wait
            os.environ.setdefault("RAY_gcs_server_port_wait_time_s", str(JOIN_TRIES))
            try:
                ray.init(address=address, **quiet)
            except (ConnectionError, RuntimeError, ValueError, TimeoutError) as exc:
                raise SceneError(f"--address {address}: cannot join that Ray cluster "
                                 f"({type(exc).__name__}: {str(exc).strip()[:160]})") from None
        else:
            ray.init(num_cpus=workers or os.cpu_count() or 1, **quiet)
    cpus = int(ray.cluster_resources().get("CPU", 1))
    return started, max(1, min(cpus, workers) if workers else cpus)


def run(out: Path, settings: Settings, splits=dataset.SPLITS, workers: int | None = None,
        address: str | None = None, verify: bool = False, command: str = "", stream=sys.stderr) -> Result:
    """Make every missing room of `splits` under `out` (see the module docstring)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    manifest = Manifest(out, settings, command)
    shards = plan(settings, splits)
    todo: list[tuple[Shard, int]] = []
    waiting: dict[Shard, set[str]] = {}     # shard -> rooms still to come
    skipped = 0
    for shard in shards:
        folder = out / shard.split
        if shard_ok(folder / shard.name, shard, settings, manifest.shards(shard.split).get(shard.name), verify):
            skipped += len(shard.indices)
            continue
        manifest.record(shard, None)
        missing = set()
        for room, index in zip(shard.rooms(), shard.indices):
            pending = folder / "pending" / f"{room}.npz"
            if pending.exists() and room_ok(pending.read_bytes(), settings.generator(shard.split, index),
                                            settings.probes):
                skipped += 1
            else:
                missing.add(room)
                todo.append((shard, index))
        waiting[shard] = missing
    failed: dict[str, str] = {}
    for shard in [s for s, rooms in waiting.items() if not rooms]:   # finished before a stop, not packed
        manifest.record(shard, pack(out / shard.split, shard, settings, failed))
    total = sum(len(s.indices) for s in shards)
    progress = Progress(total, total - len(todo), stream)
    manifest.save(settings, 0, 0.0, 0.0, workers or 0)
    cpus = 0
    if todo:
        started, cpus = start_ray(workers, address)
        progress.show()
        try:
            _schedule(todo, waiting, out, settings, manifest, progress, failed, cpus)
        finally:
            import ray

            if started:
                ray.shutdown()
    progress.close()
    elapsed = progress.elapsed()
    manifest.data["failed"].update(failed)
    manifest.save(settings, progress.made, progress.seconds, elapsed if progress.made else 0.0, cpus)
    return Result(progress.made, skipped, sorted(failed), elapsed, cpus, progress.rate())


def _schedule(todo, waiting, out: Path, settings: Settings, manifest: Manifest, progress: Progress,
              failed: dict[str, str], cpus: int) -> None:
    """Rooms in order, at most 2 per CPU in flight; each one lands in pending/ as it comes back, and a
    shard is packed once its last room is in."""
    import ray

    task = ray.remote(num_cpus=1, max_retries=2)(make_room)
    queue = list(reversed(todo))
    flight: dict = {}
    while queue or flight:
        while queue and len(flight) < 2 * cpus:
            shard, index = queue.pop()
            flight[task.remote(settings, shard.split, index)] = (shard, index)
        ready, _ = ray.wait(list(flight), num_returns=1)
        shard, index = flight.pop(ready[0])
        room = dataset.room_name(shard.split, index)
        notes = []
        try:
            name, payload, seconds = ray.get(ready[0])
            write_pending(out / shard.split, name, payload)
        except ray.exceptions.RayError as exc:  # the task raised, or its worker died (retried twice)
            failed[room] = str(exc).strip().splitlines()[-1][:300]
            seconds = 0.0
            notes.append(f"FAILED {room}: {failed[room]}")
        waiting[shard].discard(room)
        if not waiting[shard]:
            manifest.record(shard, pack(out / shard.split, shard, settings, failed))
            notes.append(f"packed {shard.split}/{shard.name}")
        progress.step(shard.split, seconds, notes)
        if notes:
            manifest.data["failed"].update(failed)
            manifest.save(settings, progress.made, progress.seconds, progress.elapsed(), cpus)
