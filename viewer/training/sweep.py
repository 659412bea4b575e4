"""Model no bigger than the scene needs: ProbeNet from ~1k to ~1M parameters and at two probe
resolutions, error against size and against inference time; the smallest model within 10% of the best
error is exported to models/probenet.onnx with its card.

    python -m viewer.training.sweep --data data/gi-v2 [--epochs 24] [--final-epochs 60]
    python -m viewer.training.sweep --data data/gi-v2 --compare-runs runs/a runs/b ... --probes 24
    python -m viewer.training.sweep --measure-shipped

The second form compares finished `viewer.training.train` runs (trained alike, in the background: on
thousands of rooms a candidate takes an hour, more than one command should) and ships the smallest
within 10% of the best, at the epoch each run kept. The third measures the shipped model again on the
encoding this viewer feeds it (which can be newer than the one it was trained on) and puts the numbers
on its card and in the docs' tables.

For every configuration: train (runs/sweep/<name>/), export to ONNX, time onnxruntime on the encoded
Cornell box (median of 20 runs, one thread), and measure the relative RMSE of `sample --method neural`
against Mitsuba at 500 free-space points of every evaluation scene (the same points and references as
docs/ACCURACY.md). Writes docs/data/neural_sweep.json, docs/images/neural_sweep.png and the sweep table
of docs/ACCURACY.md; the chosen configuration is trained again for --final-epochs and shipped.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from viewer.neural import encoding
from viewer.reference import mitsuba as reference
from viewer import scene as scenes
from viewer.evaluation.error import PUBLIC_BOX, relative_rmse
from viewer.evaluation.points import free_space_points
from viewer.neural.field import NeuralField
from viewer.rays.voxels import voxelize

ROOT = Path(__file__).resolve().parents[2]
EVALUATION_SCENES = ("cornell", "paper-test", "paper-train-1", "paper-train-2", "paper-train-3",
                     "paper-train-4", "paper-train-5")
WITHIN = 0.10
"""The shipped model is the smallest whose error is within this fraction of the best one's."""


@dataclass(frozen=True)
class Candidate:
    width: int
    hidden: int
    levels: int
    probes: int

    @property
    def name(self) -> str:
        return f"probenet-w{self.width}-h{self.hidden}-l{self.levels}-m{self.probes}"


CANDIDATES = (
    Candidate(2, 4, 2, 16), Candidate(4, 8, 3, 16), Candidate(8, 16, 3, 16), Candidate(16, 32, 3, 16),
    Candidate(32, 64, 3, 16), Candidate(8, 16, 3, 8), Candidate(16, 32, 3, 8),
)


def evaluation_set(points: int = 500) -> list[tuple[scenes.Scene, np.ndarray, np.ndarray]]:
    """(scene, free-space points, Mitsuba SH) for every evaluation scene (references cached on disk)."""
    out = []
    sources = list(EVALUATION_SCENES) + ([str(PUBLIC_BOX)] if PUBLIC_BOX.exists() else [])
    for source in sources:
        scene = scenes.load(source)
        p = free_space_points(scene, points, margin=0.06, seed=1)
        out.append((scene, p, reference.probe_sh(scene, p, directions=4096)))
    return out


def measure(model_path: Path, evaluation) -> dict:
    """Relative RMSE per scene against Mitsuba, its worst and mean, and onnxruntime milliseconds on the
    Cornell box."""
    field = NeuralField(model_path)
    errors = {}
    for scene, points, truth in evaluation:
        grid = field.solve(scene, include_emitted=True)
        errors[scene.name] = relative_rmse(grid.interpolate(points), truth)
    return {"errors": errors, "worst_error": max(errors.values()), "mean_error": float(np.mean(list(errors.values()))),
            **time_inference(field)}


def time_inference(field: NeuralField, repeats: int = 20, resolution: int | None = None) -> dict:
    """Median milliseconds of the neural update on the Cornell box: encode, onnxruntime, unpack, each
    from scratch (a new scene: an edit reuses most of the encoding, `python -m viewer.bench.neural`);
    voxelizing and listing the occluders, done once, are not counted."""
    scene = scenes.load("cornell")
    voxels = voxelize(scene, field.card.voxels)
    blockers = encoding.occluders(scene, voxels)
    lo, hi = scene.bounds
    parts: dict[str, list[float]] = {"encode": [], "network": [], "unpack": []}
    for i in range(repeats + 3):
        timings: dict[str, float] = {}
        field.predict(voxels, scene.sun, lo, hi, blockers, include_emitted=False, timings=timings,
                      resolution=resolution, reuse=False)
        if i >= 3:
            for k in parts:
                parts[k].append(1000 * timings[k])
    ms = {k: float(np.median(v)) for k, v in parts.items()}
    return {"ms": ms, "ms_total": float(np.median(np.sum([parts[k] for k in parts], axis=0)))}


def run_candidate(candidate: Candidate, data: Path, epochs: int, runs: Path, evaluation, force: bool = False) -> dict:
    from viewer.training import export as exporter
    from viewer.training.models import ProbeNet, ProbeNetConfig, parameter_count
    from viewer.training.samples import ENCODING_VOXELS, load_split, training_split
    from viewer.training.train import TrainSettings, train

    run = runs / f"{candidate.name}-e{epochs}"
    result_path = run / "result.json"
    if result_path.exists() and not force:
        return json.loads(result_path.read_text())
    m = candidate.probes
    train_set, val_set = training_split(data, m), load_split(data, "val", m)
    config = ProbeNetConfig(width=candidate.width, hidden=candidate.hidden, levels=candidate.levels)
    model = ProbeNet(config)
    start = time.perf_counter()
    history = train(model, train_set, val_set, TrainSettings(epochs=epochs), run=run)
    seconds = time.perf_counter() - start
    scene = scenes.load("paper-test")
    inputs = encoding.encode_scene(scene, m, ENCODING_VOXELS).inputs
    training = {"data": str(data), "scenes": len(train_set), "epochs": epochs, "seconds": seconds,
                "command": f"python -m viewer.training.sweep --data {data}"}
    path = run / f"{candidate.name}.onnx"
    exporter.export(run, path, m, inputs, training, {"val_relative_rmse_probes": history.val_relative_rmse[-1]})
    result = {"candidate": candidate.__dict__, "name": candidate.name, "parameters": parameter_count(model),
              "epochs": epochs, "train_seconds": seconds, "val_relative_rmse": history.val_relative_rmse[-1],
              "onnx": str(path), **measure(path, evaluation)}
    result_path.write_text(json.dumps(result, indent=1))
    return result


def choose(results: list[dict]) -> dict:
    """The smallest model (parameters) whose mean error is within WITHIN of the best mean error."""
    best = min(r["mean_error"] for r in results)
    eligible = [r for r in results if r["mean_error"] <= best * (1 + WITHIN)]
    return min(eligible, key=lambda r: (r["parameters"], r["mean_error"]))


def plot(results: list[dict], chosen: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), dpi=110)
    for ax, key, label in ((axes[0], "parameters", "parameters"), (axes[1], "ms_total", "neural update, ms (1 thread)")):
        for probes, marker in zip(sorted({r["candidate"]["probes"] for r in results}, reverse=True), "osD^"):
            rows = sorted((r for r in results if r["candidate"]["probes"] == probes), key=lambda r: r[key])
            if rows:
                ax.plot([r[key] for r in rows], [100 * r["mean_error"] for r in rows], marker=marker,
                        label=f"{probes}^3 probes, mean")
                ax.scatter([r[key] for r in rows], [100 * r["worst_error"] for r in rows], marker=marker,
                           facecolors="none", edgecolors="grey", label=f"{probes}^3 probes, worst scene")
        ax.scatter([chosen[key]], [100 * chosen["mean_error"]], s=160, facecolors="none", edgecolors="red",
                   label="shipped")
        if key == "parameters":
            ax.set_xscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel("rel. RMSE vs Mitsuba (%)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle("ProbeNet: error against size and time")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv=None) -> int:
    from viewer.cli_parsing import add_data, tool_parser

    parser = tool_parser(__doc__, prog="python -m viewer.training.sweep")
    add_data(parser)
    parser.add_argument("--epochs", type=int, default=24)
    parser.add_argument("--final-epochs", type=int, default=60)
    parser.add_argument("--runs", type=Path, default=Path("runs/sweep"))
    parser.add_argument("--probes", type=int, default=16, help="probe lattice of --ship-run")
    parser.add_argument("--only", help="comma-separated candidate names")
    parser.add_argument("--no-ship", action="store_true", help="do not retrain and export the chosen model")
    parser.add_argument("--speed-only", action="store_true", help="only time the shipped model (docs/PERFORMANCE.md)")
    parser.add_argument("--measure-shipped", action="store_true",
                        help="measure the shipped model again on this viewer's encoding and put it on its card")
    parser.add_argument("--ship-run", type=Path, help="ship this finished training run (a `viewer.training.train` "
                                                       "folder) instead of sweeping")
    parser.add_argument("--compare-runs", type=Path, nargs="+", metavar="RUN",
                        help="sweep these finished training runs instead of training the candidates")
    args = parser.parse_args(argv)
    if args.compare_runs:
        evaluation = evaluation_set()
        results = [measure_run(run, args, evaluation) for run in args.compare_runs]
        return report_sweep(results, args, ship=not args.no_ship)
    if args.ship_run:
        final = ship_run(args.ship_run, args, evaluation_set())
        write_shipped_tables(final)
        return 0
    if args.measure_shipped:
        write_shipped_tables(measure_shipped(evaluation_set()))
        return 0
    if args.speed_only:
        shipped = json.loads((ROOT / "models" / "probenet.json").read_text())
        write_shipped_tables({"errors": shipped["metrics"]["relative_rmse_vs_mitsuba"],
                              "parameters": shipped["parameters"]})
        return 0
    evaluation = evaluation_set()
    results = []
    for candidate in CANDIDATES:
        if args.only and candidate.name not in args.only.split(","):
            continue
        result = run_candidate(candidate, args.data, args.epochs, args.runs, evaluation)
        results.append(result)
        print(f"{candidate.name}: {result['parameters']} parameters, mean {100 * result['mean_error']:.1f}%, "
              f"worst {100 * result['worst_error']:.1f}%, {result['ms_total']:.1f} ms", file=sys.stderr)
    chosen = report_sweep(results, args, ship=False)
    if not args.no_ship:
        final = ship(Candidate(**chosen["candidate"]), args, evaluation)
        write_shipped_tables(final)
    return 0


def report_sweep(results: list[dict], args, ship: bool) -> dict:
    """The sweep's JSON, chart and table of docs/ACCURACY.md; with `ship`, the chosen result (already
    trained for good: `--compare-runs`) becomes models/probenet.onnx. Returns the chosen result."""
    chosen = choose(results)
    out = ROOT / "docs" / "data" / "neural_sweep.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"results": results, "chosen": chosen["name"], "within": WITHIN}, indent=1))
    plot(results, chosen, ROOT / "docs" / "images" / "neural_sweep.png")
    print(f"chosen: {chosen['name']}", file=sys.stderr)
    write_sweep_table(results, chosen, args)
    if ship:
        write_shipped_tables(install(chosen))
    return chosen


def _load_line() -> str:
    import os

    return f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"


def write_sweep_table(results: list[dict], chosen: dict, args) -> None:
    from viewer.evaluation.report import replace_block

    rows = ["| model | probes | parameters | epochs | mean rel. RMSE | worst scene | neural update (ms) |",
            "|---|---|---|---|---|---|---|"]
    for r in sorted(results, key=lambda r: (r["candidate"]["probes"], r["parameters"])):
        mark = " **(chosen)**" if r["name"] == chosen["name"] else ""
        epochs = f"{r['epochs']} (kept {r['kept_epoch']})" if "kept_epoch" in r else r["epochs"]  # a run's best
        rows.append(f"| {r['name']}{mark} | {r['candidate']['probes']}^3 | {r['parameters']} | {epochs} | "
                    f"{100 * r['mean_error']:.1f}% | {100 * r['worst_error']:.1f}% | {r['ms_total']:.1f} |")
    command = (f"python -m viewer.training.sweep --data {args.data} --compare-runs "
               f"{' '.join(str(r) for r in args.compare_runs)} --probes {args.probes}" if args.compare_runs
               else f"python -m viewer.training.sweep --data {args.data} --epochs {args.epochs}")
    trained = sorted({r.get("training_rooms") for r in results if r.get("training_rooms")})
    rooms = f" on {', '.join(f'{n:,}' for n in trained)} training rooms" if trained else ""
    block = ("\n".join(rows) + f"\n\n![error against size and time](images/neural_sweep.png)\n\n"
             f"Every model trained{rooms}, the same epochs and steps; errors at the epoch each run kept. "
             f"Command: `{command}`; "
             f"timings measured at {_load_line()} (one onnxruntime thread).\n")
    replace_block(ROOT / "docs" / "ACCURACY.md", "<!-- neural-sweep -->", block, "# Accuracy")


def write_shipped_tables(final: dict) -> None:
    from viewer.evaluation.report import replace_block

    rows = ["| scene | rel. RMSE vs Mitsuba |", "|---|---|"]
    rows += [f"| {name} | {100 * error:.1f}% |" for name, error in final["errors"].items()]
    replace_block(ROOT / "docs" / "ACCURACY.md", "<!-- neural-accuracy -->",
                  "\n".join(rows) + f"\n\nModel: models/probenet.onnx ({final['parameters']} parameters). Command: "
                  "`python -m viewer sample SCENE --points P.npy --method neural --out SH.npy` against "
                  "Mitsuba at 500 free-space points per scene (`python -m viewer.training.sweep`).\n", "# Accuracy")
    field = NeuralField(ROOT / "models" / "probenet.onnx")
    rows = ["| probes | encode (ms) | onnxruntime (ms) | unpack (ms) | total (ms) |", "|---|---|---|---|---|"]
    for m in (16, 24):
        t = time_inference(field, resolution=m)
        rows.append(f"| {m}^3 | {t['ms']['encode']:.2f} | {t['ms']['network']:.2f} | {t['ms']['unpack']:.2f} | "
                    f"{t['ms_total']:.2f} |")
    replace_block(ROOT / "docs" / "PERFORMANCE.md", "<!-- neural-speed -->",
                  "\n".join(rows) + f"\n\nThe Cornell box, median of 20 updates after 3 warm-up runs, one onnxruntime "
                  f"thread, {_load_line()}. Command: `python -m viewer.training.sweep --speed-only`.\n", "# Performance")


def ship_run(run: Path, args, evaluation) -> dict:
    """Export a finished `viewer.training.train` run, measure it like a sweep candidate, and ship it."""
    return install(measure_run(run, args, evaluation))


def trained_epochs(run: Path) -> int:
    """How many epochs a `viewer.training.train` run went through (its latest checkpoint's history)."""
    import torch

    return len(torch.load(Path(run) / "checkpoint.pt", weights_only=False)["history"]["epochs"])


def measure_run(run: Path, args, evaluation) -> dict:
    """A finished `viewer.training.train` run exported (its kept epoch) into `run` as <candidate name>.onnx
    with its card, and measured like a sweep candidate."""
    import torch

    from viewer.training import export as exporter
    from viewer.training.dataset import room_refs
    from viewer.training.samples import ENCODING_VOXELS, training_split

    state = torch.load(exporter.shipped_checkpoint(run), weights_only=False)
    history = state["history"]   # up to the shipped epoch (the best, where the run kept one)
    config = state["config"]
    m = args.probes
    scene = scenes.load("paper-test")
    inputs = encoding.encode_scene(scene, m, ENCODING_VOXELS, direct_shadows=encoding.DIRECT_SHADOWS).inputs
    recorded = run / "data.json"   # what the run trained on (train.record_data): the dataset may have grown
    train_scenes = (json.loads(recorded.read_text())["training_rooms"] if recorded.exists()
                    else len(training_split(args.data, m, quiet=True)))
    training = {"data": str(args.data), "scenes": train_scenes, "epochs": len(history["epochs"]),
                "seconds": float(sum(history["seconds"])),
                "command": f"python -m viewer.training.train --data {args.data} --out {run} --width {config['width']} "
                           f"--hidden {config['hidden']} --epochs {len(history['epochs'])} --batch 2"}
    manifest = json.loads((args.data / "manifest.json").read_text()) if (args.data / "manifest.json").exists() else {}
    files = {split: len(room_refs(args.data, split)) for split in ("train", "val", "paper")}
    truth = manifest.get("settings", manifest).get("truth", "mitsuba")  # format 2 keeps it in "settings"
    training["dataset"] = {"command": manifest.get("command"), "truth": truth, "files_used": files}
    if recorded.exists():
        training.update(json.loads(recorded.read_text()))
    if history.get("val_metrics"):   # the kept epoch's validation: all the light and the reflected light
        training["final_val"] = history["val_metrics"][-1]
    candidate = Candidate(config["width"], config["hidden"], config["levels"], m)
    path = run / f"{candidate.name}.onnx"   # named by its size: the benchmark lists every sweep model
    card = exporter.export(run, path, m, inputs, training,
                           {"val_relative_rmse_probes": history["val_relative_rmse"][-1]})
    final = {"candidate": candidate.__dict__, "name": candidate.name, "run": str(run), "parameters": card["parameters"],
             "epochs": trained_epochs(run), "kept_epoch": len(history["epochs"]), "training_rooms": train_scenes,
             "train_seconds": training["seconds"], "val_relative_rmse": history["val_relative_rmse"][-1],
             "onnx": str(path), **measure(path, evaluation)}
    print(f"{run}: {final['parameters']} parameters, mean {100 * final['mean_error']:.1f}%, "
          f"worst {100 * final['worst_error']:.1f}%, {final['ms_total']:.1f} ms", file=sys.stderr)
    return final


def measure_shipped(evaluation) -> dict:
    """models/probenet.onnx measured as a sweep candidate on the encoding this viewer feeds it, which may be
    newer than the one it was trained on (`encoding.VERSION_CHANNELS`): its card's metrics made again."""
    target = ROOT / "models" / "probenet.onnx"
    card = json.loads(target.with_suffix(".json").read_text())
    final = {"onnx": str(target), "parameters": card["parameters"], **measure(target, evaluation)}
    return install(final)


def ship(candidate: Candidate, args, evaluation) -> dict:
    """Train the chosen configuration longer and export it as models/probenet.onnx with its card."""
    return install(run_candidate(candidate, args.data, args.final_epochs, args.runs, evaluation))


def install(final: dict) -> dict:
    """Copy a measured model to models/probenet.onnx and complete its card."""
    import shutil

    target = ROOT / "models" / "probenet.onnx"
    target.parent.mkdir(exist_ok=True)
    if Path(final["onnx"]).resolve() != target.resolve():
        shutil.copy(final["onnx"], target)
    card = json.loads(Path(final["onnx"]).with_suffix(".json").read_text())
    card["name"], card["file"] = "probenet", "probenet.onnx"
    card["metrics"].update({"relative_rmse_vs_mitsuba": final["errors"], "worst_relative_rmse": final["worst_error"],
                            "mean_relative_rmse": final["mean_error"], "milliseconds_cornell": final["ms"],
                            "evaluation": "500 free-space points per scene, Mitsuba 4096 directions "
                                          "(viewer.evaluation.points.free_space_points, seed 1)",
                            "measured_on_encoding_version": encoding.VERSION})
    card["selection"] = f"smallest of the sweep within {int(100 * WITHIN)}% of the best mean error (docs/ACCURACY.md)"
    target.with_suffix(".json").write_text(json.dumps(card, indent=1) + "\n")
    print(f"shipped {target} ({final['parameters']} parameters, worst scene {100 * final['worst_error']:.1f}%)",
          file=sys.stderr)
    return final


if __name__ == "__main__":
    raise SystemExit(main())
