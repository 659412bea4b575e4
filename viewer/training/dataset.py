"""The neural GI model's dataset: scenes with their ground-truth probe SH, one `.npz` per scene.

    python -m viewer.training.dataset --out data/gi-v1 --count 800 --seed 1 --probes 8,16 --directions 256

Layout under --out:
    manifest.json        command line, seed, counts, truth, directions, versions; updated as files land
    paper/{name}.npz     the fixed scenes: paper-train-1..5, paper-test, cornell (made first)
    val/{index:05d}.npz  procedural rooms, count - round(0.9 count) of them (made second)
    train/{index:05d}.npz procedural rooms, round(0.9 count) of them

Scene i of a procedural split comes from `np.random.default_rng([seed, split_id, i])` (train 0, val 1),
so any one file can be regenerated alone. Keys of one file (`FORMAT` below):
    name, params, generator   JSON strings: scene name, the drawn parameters, how the file was made
    vertices (V, 3) float32, faces (F, 3) int32, albedo (F, 3) float16, emission (F, 3) float32,
    face_group (F,) int16, groups (JSON list of names), sun (6,) float64 direction + irradiance or (0,),
    camera (10,) float64 origin, target, up, fov
    lo, hi (3,) float64      the probe box: scene.bounds, as `viewer.gi.solve` uses
    sh_{M} (M, M, M, 9, 3) float32        ground-truth incident-radiance SH at the probe centres
    sh_{M}_filled (M, M, M, 9, 3) float32 the same with invalid probes filled (`probes.fill_invalid`)
    sh_{M}_direct (M, M, M, 9, 3) float32 the part of sh_{M} straight from emitters and the sun (raw;
                                          sh_{M} - sh_{M}_direct is the reflected light the renderer's
                                          probes hold, since it shades emitters and the sun itself)
    valid_{M} (M, M, M) bool              False for probes inside solid objects
    seconds () float64       time spent making the file
The scene is stored exactly as the truth saw it (rounded to the stored precisions first).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterator

import numpy as np

from viewer.reference import ReferenceUnavailable
from viewer.scene import Camera, DirectionalLight, Scene, SceneError, load
from viewer.training import procedural, truth as truths

FORMAT = 1
SPLITS = ("paper", "val", "train")
"""In the order they are made: the fixed scenes first, so that training can start on them."""
SPLIT_IDS = {"train": 0, "val": 1, "paper": 2}
PAPER_SCENES = ("paper-train-1", "paper-train-2", "paper-train-3", "paper-train-4", "paper-train-5",
                "paper-test", "cornell")
TRAIN_FRACTION = 0.9


# ---- one example ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Example:
    path: Path
    scene: Scene
    lo: np.ndarray
    """(3,) lower corner of the probe box (scene.bounds)."""
    hi: np.ndarray
    targets: dict[int, np.ndarray]
    """{M: (M, M, M, 9, 3)} ground-truth SH with invalid probes filled from valid neighbours (what the
    renderer samples); `raw` has them as traced."""
    raw: dict[int, np.ndarray]
    direct: dict[int, np.ndarray]
    """{M: (M, M, M, 9, 3)} the part of `raw` straight from the emitters and the sun."""
    valid: dict[int, np.ndarray]
    """{M: (M, M, M) bool} False inside solid objects."""
    params: dict
    generator: dict


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


def load_example(path) -> Example:
    path = Path(path)
    with np.load(path) as data:
        resolutions = sorted(int(k[3:]) for k in data.files if k.startswith("sh_") and k[3:].isdigit())
        return Example(path=path, scene=scene_from_arrays(data), lo=data["lo"], hi=data["hi"],
                       targets={m: data[f"sh_{m}_filled"] for m in resolutions},
                       raw={m: data[f"sh_{m}"] for m in resolutions},
                       direct={m: data[f"sh_{m}_direct"] for m in resolutions},
                       valid={m: data[f"valid_{m}"] for m in resolutions},
                       params=json.loads(str(data["params"])), generator=json.loads(str(data["generator"])))


def iter_split(root, split: str) -> Iterator[Example]:
    """The examples of one split (`train`, `val` or `paper`), in file-name order."""
    for path in sorted((Path(root) / split).glob("*.npz")):
        yield load_example(path)


def is_complete(path: Path, generator: dict, resolutions) -> bool:
    """Whether the file exists, reads back whole (every member's CRC), was made with the same settings
    and holds finite targets of the right shapes for every resolution."""
    if not path.exists():
        return False
    try:
        with np.load(path) as data:
            arrays = {k: data[k] for k in data.files}
        if json.loads(str(arrays["generator"])) != generator:
            return False
        for m in resolutions:
            for key, shape in ((f"sh_{m}", (m, m, m, 9, 3)), (f"sh_{m}_filled", (m, m, m, 9, 3)),
                               (f"sh_{m}_direct", (m, m, m, 9, 3)), (f"valid_{m}", (m, m, m))):
                if arrays[key].shape != shape or not np.all(np.isfinite(arrays[key])):
                    return False
        scene_from_arrays(arrays)
    except Exception:  # noqa: BLE001 - truncated, corrupt, old or foreign: make it again
        return False
    return True


def save(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write through a temporary file, so that an interrupted run leaves no half file behind."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    os.replace(tmp, path)


# ---- making one file -----------------------------------------------------------------------------------

@dataclass(frozen=True)
class Job:
    split: str
    index: int
    path: Path
    generator: dict
    """JSON-able: seed, split, index, truth, directions, format (stored, and checked when resuming)."""
    resolutions: tuple[int, ...]
    truth: str
    solver_voxels: int


def split_sizes(count: int) -> dict[str, int]:
    """Files per split: round(0.9 count) procedural rooms to train, the rest (at least one when count >= 2)
    to val, and the fixed scenes."""
    n_train = min(int(round(TRAIN_FRACTION * count)), max(count - 1, 1))
    return {"paper": len(PAPER_SCENES), "val": count - n_train, "train": n_train}


def jobs(out: Path, seed: int, count: int, resolutions, truth: str, directions: int,
         solver_voxels: int, splits=SPLITS) -> list[Job]:
    sizes = split_sizes(count)
    out_jobs = []
    for split in [s for s in SPLITS if s in splits]:
        for i in range(sizes[split]):
            name = PAPER_SCENES[i] if split == "paper" else f"{i:05d}"
            generator = {"format": FORMAT, "seed": seed, "split": split, "index": i, "truth": truth,
                         "directions": directions}
            if truth == "solver":
                generator["solver_voxels"] = solver_voxels
            out_jobs.append(Job(split, i, out / split / f"{name}.npz", generator, tuple(resolutions),
                                truth, solver_voxels))
    return out_jobs


def make_scene(split: str, index: int, seed: int) -> tuple[Scene, dict]:
    if split == "paper":
        scene = load(PAPER_SCENES[index])
        return quantized(scene), {"source": "builtin", "name": scene.name}
    rng = np.random.default_rng([seed, SPLIT_IDS[split], index])
    scene, params = procedural.random_scene(rng, f"{split}-{index:05d}")
    return quantized(scene), params


def prepare(job: Job):
    """The numpy part of a file: the scene, its probe box and probe validity."""
    clock = time.perf_counter()
    scene, params = make_scene(job.split, job.index, job.generator["seed"])
    lo, hi = scene.bounds
    valid = truths.probe_validity(scene, lo, hi, job.resolutions) if job.truth == "mitsuba" else None
    return scene, params, lo, hi, valid, time.perf_counter() - clock


def finish(job: Job, prepared) -> float:
    """The truth (Mitsuba's threads, or the solver) and the file; returns the seconds spent in all."""
    scene, params, lo, hi, valid, seconds = prepared
    clock = time.perf_counter()
    seed = int(np.random.default_rng([job.generator["seed"], SPLIT_IDS[job.split], job.index, 0x7E]).integers(2**31))
    arrays = truths.targets(scene, lo, hi, job.resolutions, job.truth, job.generator["directions"], seed,
                            valid, job.solver_voxels)
    seconds += time.perf_counter() - clock
    arrays.update(scene_arrays(scene))
    arrays.update(lo=np.asarray(lo, np.float64), hi=np.asarray(hi, np.float64),
                  params=np.array(json.dumps(params)), generator=np.array(json.dumps(job.generator)),
                  seconds=np.array(seconds, np.float64))
    job.path.parent.mkdir(parents=True, exist_ok=True)
    save(job.path, arrays)
    return seconds


# ---- the run -------------------------------------------------------------------------------------------

class Progress:
    """`[val] 12/887  0.21 files/s  ETA 1:09:40` on stderr: rewritten in place on a terminal, one line
    per file in a log."""

    def __init__(self, total: int, stream=sys.stderr):
        self.total, self.done, self.made, self.stream = total, 0, 0, stream
        self.start = time.perf_counter()
        self.tty = stream.isatty()

    def step(self, split: str, made: bool) -> None:
        self.done += 1
        self.made += made
        elapsed = time.perf_counter() - self.start
        rate = self.made / elapsed if self.made and elapsed > 0 else 0.0
        eta = (self.total - self.done) / rate if rate > 0 else float("nan")
        eta_text = time.strftime("%H:%M:%S", time.gmtime(eta)) if np.isfinite(eta) else "?"
        line = (f"[{split}] {self.done}/{self.total}  {rate:.3f} files/s  "
                f"{elapsed / max(self.made, 1):.1f} s/file  ETA {eta_text}")
        self.stream.write(("\r" + line) if self.tty else line + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")


def versions(truth: str) -> dict:
    out = {"python": platform.python_version(), "numpy": np.__version__}
    try:
        from importlib.metadata import version

        out["gi-viewer"] = version("gi-viewer")
    except Exception:  # noqa: BLE001
        pass
    if truth == "mitsuba":
        import drjit
        import mitsuba

        from viewer import reference

        out.update(mitsuba=mitsuba.__version__, drjit=drjit.__version__, variant=reference.variant())
    try:
        out["commit"] = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                                       cwd=Path(__file__).parent, timeout=10).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        pass
    return out


class Manifest:
    """manifest.json: what the dataset is and how far it got, rewritten after every file."""

    SETTINGS = ("seed", "count", "truth", "directions", "probes")

    def __init__(self, out: Path, settings: dict, counts: dict, command: str):
        self.path = out / "manifest.json"
        old = json.loads(self.path.read_text()) if self.path.exists() else None
        if old is not None and any(old.get(k) != settings[k] for k in self.SETTINGS):
            differ = ", ".join(f"{k} {old.get(k)} != {settings[k]}" for k in self.SETTINGS
                               if old.get(k) != settings[k])
            raise SceneError(f"{out} holds a dataset made with other settings ({differ}): "
                             "use another --out, or the same settings to resume")
        self.data = {**settings, "format": FORMAT, "command": command, "versions": versions(settings["truth"]),
                     "splits": {s: {"count": counts[s], "done": 0} for s in SPLITS},
                     "seconds_per_file": None, "started": (old or {}).get("started") or _now()}

    def update(self, done: dict, seconds: list[float]) -> None:
        for s in SPLITS:
            self.data["splits"][s]["done"] = done[s]
        if seconds:
            self.data["seconds_per_file"] = float(np.mean(seconds))
        self.data["updated"] = _now()
        tmp = self.path.with_name("manifest.json.tmp")
        tmp.write_text(json.dumps(self.data, indent=2) + "\n")
        os.replace(tmp, self.path)


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


def generate(out: Path, count: int, seed: int, resolutions, directions: int, truth: str,
             solver_voxels: int = 32, splits=SPLITS, command: str = "", stream=sys.stderr) -> dict:
    """Make every missing file of `splits` under `out`. Returns {"made": n, "skipped": n, "seconds": [the
    time spent on each file made], "elapsed": wall-clock seconds of the whole run}."""
    out.mkdir(parents=True, exist_ok=True)
    todo_all = jobs(out, seed, count, resolutions, truth, directions, solver_voxels, splits)
    counts = split_sizes(count)
    settings = {"seed": seed, "count": count, "truth": truth, "directions": directions,
                "probes": list(resolutions)}
    manifest = Manifest(out, settings, counts, command)
    done = {s: 0 for s in SPLITS}
    progress = Progress(len(todo_all), stream)
    todo = []
    for job in todo_all:
        if is_complete(job.path, job.generator, job.resolutions):
            done[job.split] += 1
            progress.step(job.split, False)
        else:
            todo.append(job)
    manifest.update(done, [])
    seconds = []
    # One process: Mitsuba's LLVM threads use both cores already. Making the scenes and their probe
    # validity ahead in a process pool measured no faster on this 2-core machine (6-8 s a file either way).
    for job in todo:
        seconds.append(finish(job, prepare(job)))
        done[job.split] += 1
        manifest.update(done, seconds)
        progress.step(job.split, True)
    progress.close()
    return {"made": len(todo), "skipped": len(todo_all) - len(todo), "seconds": seconds,
            "elapsed": time.perf_counter() - progress.start}


# ---- exporting a scene for a look ----------------------------------------------------------------------

def write_obj(scene: Scene, path: Path) -> None:
    """OBJ + MTL + sidecar JSON (camera, sun) that `viewer.scene.load` reads back to the same scene (one
    material per group: every group of a generated scene has one albedo and one emission)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    obj, mtl = [f"mtllib {path.stem}.mtl\n"], []
    first = 1  # OBJ indices count from 1 over the whole file
    for g, group in enumerate(scene.groups):
        faces = scene.faces[scene.face_group == g]
        if not len(faces):
            continue
        used, local = np.unique(faces, return_inverse=True)
        obj.append(f"g {group}\nusemtl {group}\n")
        obj += [f"v {x!r} {y!r} {z!r}\n" for x, y, z in scene.vertices[used].tolist()]
        obj += [f"f {a + first} {b + first} {c + first}\n" for a, b, c in local.reshape(-1, 3).tolist()]
        first += len(used)
        albedo, emission = scene.albedo[scene.face_group == g][0], scene.emission[scene.face_group == g][0]
        mtl.append(f"newmtl {group}\nKd {' '.join(map(repr, albedo.tolist()))}\n"
                   f"Ke {' '.join(map(repr, emission.tolist()))}\n")
    path.write_text("".join(obj))
    path.with_suffix(".mtl").write_text("".join(mtl))
    c = scene.camera
    side = {"camera": {"origin": list(c.origin), "target": list(c.target), "up": list(c.up), "fov": c.fov}}
    if scene.sun is not None:
        side["sun"] = {"direction": scene.sun.direction.tolist(), "irradiance": scene.sun.irradiance.tolist()}
    path.with_suffix(".json").write_text(json.dumps(side, indent=2) + "\n")


# ---- command line --------------------------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m viewer.training.dataset",
        description="Generate the neural GI dataset: procedural Cornell-box rooms (train/, val/) and the "
                    "fixed paper scenes (paper/), each with ground-truth probe SH over scene.bounds, one "
                    ".npz per scene. Resumable: finished files are kept, missing or corrupt ones are made "
                    "again. Order: paper, val, train.",
        epilog="example: python -m viewer.training.dataset --out data/gi-v1 --count 800 --seed 1 "
               "--probes 8,16 --directions 256")
    p.add_argument("--out", type=Path, help="dataset folder (created; holds manifest.json and the splits)")
    p.add_argument("--count", type=int, default=800,
                   help="procedural scenes: round(0.9 count) in train/, the rest in val/ (default 800)")
    p.add_argument("--seed", type=int, default=1, help="scene i of a split is default_rng([seed, split, i])")
    p.add_argument("--probes", default="8,16", help="probe resolutions M, comma separated (default 8,16)")
    p.add_argument("--directions", type=int, default=256,
                   help="directions per probe for the truth (Mitsuba: stratified rays with light sampling)")
    p.add_argument("--truth", choices=truths.TRUTHS, default=None,
                   help="ground truth: mitsuba (default when Mitsuba 3 is installed) or solver "
                        "(viewer.gi.solve, ~30 s a scene)")
    p.add_argument("--solver-voxels", type=int, default=32, help="voxels per axis for --truth solver")
    p.add_argument("--splits", default=",".join(SPLITS),
                   help=f"splits to make, comma separated (default {','.join(SPLITS)}, in that order)")
    p.add_argument("--dump-obj", type=Path, metavar="DIR",
                   help="instead of generating: write the scenes --indices of --split as OBJ+MTL+JSON "
                        "into DIR (for `python -m viewer capture DIR/NAME.obj`)")
    p.add_argument("--split", choices=SPLITS, default="train", help="split for --dump-obj")
    p.add_argument("--indices", default="0,1,2,3", help="scene indices for --dump-obj, comma separated")
    return p


def _int_list(text: str, flag: str, low: int, high: int) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise SceneError(f"{flag} {text!r}: expected comma-separated integers") from None
    if not values or any(not low <= v <= high for v in values):
        raise SceneError(f"{flag} {text!r}: each value must be between {low} and {high}")
    return values


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.dump_obj is not None:
            for i in _int_list(args.indices, "--indices", 0, 10**6):
                scene, _ = make_scene(args.split, i, args.seed)
                write_obj(scene, args.dump_obj / f"{scene.name}.obj")
                print(args.dump_obj / f"{scene.name}.obj")
            return 0
        if args.out is None:
            parser.error("--out is required (or --dump-obj)")
        resolutions = sorted(set(_int_list(args.probes, "--probes", 2, 128)))
        if args.count < 1 or args.directions < 16:
            raise SceneError("--count must be at least 1 and --directions at least 16")
        truth = args.truth
        if truth is None:
            truth = "mitsuba" if truths.mitsuba_available() else "solver"
            if truth == "solver":
                print("Mitsuba 3 is not installed: using --truth solver", file=sys.stderr)
        elif truth == "mitsuba":
            from viewer import reference

            reference.variant()  # ReferenceUnavailable says what to install
        splits = [s.strip() for s in args.splits.split(",") if s.strip()]
        if not splits or any(s not in SPLITS for s in splits):
            raise SceneError(f"--splits {args.splits!r}: choose from {', '.join(SPLITS)}")
        command = " ".join(["python -m viewer.training.dataset", *(argv if argv is not None else sys.argv[1:])])
        result = generate(args.out, args.count, args.seed, resolutions, args.directions, truth,
                          args.solver_voxels, splits, command)
    except (SceneError, ReferenceUnavailable) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    mean = f", {result['elapsed'] / result['made']:.2f} s per file (wall clock)" if result["made"] else ""
    print(f"{args.out}: {result['made']} files made, {result['skipped']} already there{mean}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
