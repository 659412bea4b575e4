"""The neural source from an edit to its probes, stage by stage: what the neural GI is judged by.

    python -m viewer.bench.neural [SCENE ...] [--probes 16 24] [--voxels N] [--repeats 9]
                                  [--configs | --configs-only] [--write]

For each scene and probe lattice, with models/probenet.onnx (a convolutional network: it runs on any
lattice divisible by 2^levels) and the viewer's path (`viewer.neural.field.NeuralGI`): a lamp's colour and
intensity edit, an albedo edit (the largest group's, as viewer.bench.methods), the lamp moved by a
tenth of the scene, and a new scene; and `before`, what any edit cost before the incremental encoder
(voxelize, `encoding.encode`, the network on all three colour passes, a multiply and a transpose).
Medians of `repeats` runs; each stage in CPU milliseconds of the one thread everything runs on
(onnxruntime, BLAS and numba on one thread: `time.thread_time`, so that other work on the machine does
not count), the whole update also in wall-clock milliseconds, with the machine's load. `--configs`
adds the network alone at 24^3 for ProbeNet sizes exported with random weights (needs torch): what a
retrained model would cost. `--write` puts the tables into docs/PERFORMANCE.md.
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from viewer.neural import encoding
from viewer.neural import field as neural
from viewer.neural.network_feed import encoding_walls
from viewer import scene as scenes
from viewer.evaluation.report import replace_block
from viewer.neural.field import DEFAULT_MODEL, NeuralField, NeuralGI, open_session
from viewer.scene import Scene

ROOT = Path(__file__).resolve().parents[2]
MARKER = "<!-- bench-neural -->"
STAGES = ("voxels", "encode", "network", "unpack")
"""`voxels`: voxelizing and listing the occluders (a new geometry) or recolouring the kept voxels (a colour
edit)."""
CONFIGS = ("w8-h16", "w12-h24", "w16-h32", "w8-h8", "w12-h8", "w16-h8", "w4-h8", "w8-h8-hl1", "w8-h16-nearest",
           "w8-h8-nearest")
"""ProbeNet sizes for `--configs`: width, hidden; `hl1`: a one-layer head (two by default); `nearest`:
nearest upsampling instead of trilinear."""


def edits(scene: Scene) -> dict[str, Scene]:
    """The edits timed, each against `scene`."""
    from viewer.ui.scene_edits import emitter_group

    out = {}
    group = emitter_group(scene)
    if group is not None:
        radiance = scene.emission[scene.face_group == scene.group_index(group)][0]
        out["lamp colour"] = scene.with_emission(group, radiance * (1.4, 0.9, 0.5))
    largest = scene.largest_group()
    out["albedo"] = scene.with_albedo(largest, scene.group_albedo(largest)[::-1] * 0.5)
    if group is not None:
        lo, hi = scene.bounds
        move = np.eye(4)
        move[0, 3] = 0.1 * float(hi[0] - lo[0])
        out["lamp move"] = scene.transformed_group(group, move)
    return out


def _stages(timings: dict[str, float]) -> dict[str, float]:
    ms = {name: 1000 * timings.get(name, 0.0) for name in ("encode", "network", "unpack")}
    ms["voxels"] = 1000 * (timings.get("voxelize", 0.0) + timings.get("recolour", 0.0))
    return ms


def _medians(runs: list[dict[str, float]], passes: list[int]) -> dict:
    out = {name: statistics.median(r[name] for r in runs) for name in STAGES}
    out["network + encode + unpack"] = statistics.median(r["encode"] + r["network"] + r["unpack"] for r in runs)
    out["edit to probes"] = statistics.median(sum(r[name] for name in STAGES) for r in runs)
    out["wall"] = statistics.median(r["wall"] for r in runs)
    out["passes"] = max(passes)
    return out


def _update(gi: NeuralGI, scene: Scene) -> dict[str, float]:
    """One update, its stages in CPU milliseconds and the whole in wall-clock ones (`wall`)."""
    timings: dict[str, float] = {}
    clock = time.perf_counter()
    gi.update(scene, timings=timings)
    return {**_stages(timings), "wall": 1000 * (time.perf_counter() - clock)}


def measure(scene: Scene, field: NeuralField, probes: int, voxels: int, repeats: int) -> dict[str, dict]:
    """Stage medians per edit kind (see the module docstring)."""
    rows = {}
    for what, edited in edits(scene).items():
        gi = NeuralGI(field, probes, voxels)
        field.forget()
        gi.update(scene)
        flip = [scene, edited]
        runs, passes = [], []
        for _ in range(repeats):
            flip.reverse()
            runs.append(_update(gi, flip[0]))
            passes.append(field.passes_run)
        rows[what] = _medians(runs, passes)
    runs, passes = [], []
    for _ in range(repeats):
        field.forget()
        runs.append(_update(NeuralGI(field, probes, voxels), scene))
        passes.append(field.passes_run)
    rows["new scene"] = _medians(runs, passes)
    rows["before (any edit)"] = _medians([_before(scene, field, probes, voxels) for _ in range(repeats)], [3])
    return rows


def _before(scene: Scene, field: NeuralField, probes: int, voxels: int) -> dict[str, float]:
    """One update as the neural source ran before the incremental encoder: everything from scratch."""
    from viewer.neural.field import clock_now
    from viewer.rays.voxels import voxelize

    wall = time.perf_counter()
    clock = clock_now()
    grid = voxelize(scene, voxels)
    blockers = encoding.occluders(scene, grid)   # with the voxels, as NeuralGI lists them
    lo, hi = scene.bounds
    voxelized = clock_now()
    enc = encoding.encode(grid, scene.sun, lo, hi, probes, blockers)
    encoded = clock_now()
    out = field.run(enc.inputs, encoding_walls(enc))   # the filter stopped at walls, as the viewer runs it
    ran = clock_now()
    coefficients = (out[:, 9:18] * enc.scale[:, None, None, None, None]).transpose(2, 3, 4, 1, 0)
    _ = np.ascontiguousarray(coefficients, np.float32), out[:, 18].mean(axis=0) > 0.0
    done = clock_now()
    return {"voxels": 1000 * (voxelized - clock), "encode": 1000 * (encoded - voxelized),
            "network": 1000 * (ran - encoded), "unpack": 1000 * (done - ran),
            "wall": 1000 * (time.perf_counter() - wall)}


def network_configs(configs, probes: int, repeats: int) -> list[tuple[str, int, float]]:
    """(config, parameters, median ms) of onnxruntime alone on the Cornell box's encoded inputs."""
    import torch

    from viewer.neural.network_feed import feed
    from viewer.neural.network_tail import fed_names, run_graph
    from viewer.training.export import export_onnx, model_tail
    from viewer.training.export import kernels as export_kernels
    from viewer.training.models import ProbeNet, ProbeNetConfig, parameter_count

    scene = scenes.load("cornell")
    inputs = encoding.encode_scene(scene, probes, probes).inputs
    out = []
    torch.manual_seed(0)
    with tempfile.TemporaryDirectory() as folder:
        for name in configs:
            parts = name.split("-")
            config = ProbeNetConfig(width=int(parts[0][1:]), hidden=int(parts[1][1:]),
                                    head_layers=1 if "hl1" in parts else 2,
                                    upsample="nearest" if "nearest" in parts else "trilinear")
            model = ProbeNet(config).eval()
            with torch.no_grad():
                for p in model.parameters():
                    p.normal_(0.0, 0.1)   # timing only: random weights
            path = Path(folder) / f"{name}.onnx"
            export_onnx(model, path, probes)
            session = open_session(path, threads=1)
            tail = model_tail(model)   # the export ends the graph at its head (`split_tail`)
            names, kernels = fed_names([i.name for i in session.get_inputs()], tail), export_kernels(model)

            def network():   # the asinh, the seen filter and the tail included, as the field computes them
                run_graph(session, feed(names, inputs, kernels), tail)

            for _ in range(3):
                network()
            ms = []
            for _ in range(repeats):
                clock = time.thread_time()
                network()
                ms.append(1000 * (time.thread_time() - clock))
            out.append((name, parameter_count(model), statistics.median(ms)))
            print(f"network {name}: {out[-1][1]} parameters, {out[-1][2]:.2f} ms", flush=True)
    return out


def table(results: dict, model: str) -> list[str]:
    lines = [f"Model {model}; medians; the stages in CPU ms of the one thread they run on, the last column in "
             "wall-clock ms; `passes`: colour passes the network ran (3: all; 0: its output reused, scaled).", "",
             "| scene | probes | voxels | edit | voxels (voxelize + occluders, or recolour) | encode | network | passes | "
             "unpack | encode + network + unpack | edit to probes (CPU) | edit to probes (wall) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for (name, probes, voxels), rows in results.items():
        for what, r in rows.items():
            lines.append(f"| {name} | {probes}^3 | {voxels}^3 | {what} | {r['voxels']:.1f} | {r['encode']:.2f} | "
                         f"{r['network']:.2f} | {r['passes']} | {r['unpack']:.2f} | "
                         f"{r['network + encode + unpack']:.2f} | {r['edit to probes']:.1f} | {r['wall']:.1f} |")
    return lines


def main(argv=None) -> int:
    from viewer.cli_parsing import add_repeats, add_scenes, add_write, tool_parser

    parser = tool_parser(__doc__)
    add_scenes(parser)
    parser.add_argument("--probes", type=int, nargs="+", default=[16, 24])
    parser.add_argument("--voxels", type=int, nargs="+", help="voxels per axis the encoding reads (default: the "
                                                               "card's, and the probes' when they differ)")
    add_repeats(parser, 9)
    parser.add_argument("--model", type=Path, default=DEFAULT_MODEL)
    parser.add_argument("--configs", action="store_true", help="also time ProbeNet sizes at 24^3 (needs torch)")
    parser.add_argument("--configs-only", action="store_true", help="only time the ProbeNet sizes")
    add_write(parser, "write the tables into docs/PERFORMANCE.md")
    args = parser.parse_args(argv)
    neural.CLOCK = time.thread_time   # the stages' CPU time: the machine may be busy with other work
    numba.set_num_threads(1)   # the compiled loops on this thread too: another thread's time is not on its clock
    field = NeuralField(args.model)
    results = {}
    for name in [] if args.configs_only else args.scenes:
        scene = scenes.load(name)
        for probes in args.probes:
            for voxels in args.voxels or sorted({field.card.voxels, probes}):
                measure(scene, field, probes, voxels, 1)   # compile and warm up first
                results[(scene.name, probes, voxels)] = measure(scene, field, probes, voxels, args.repeats)
                print("\n".join(table({(scene.name, probes, voxels): results[(scene.name, probes, voxels)]},
                                      args.model.name)[4:]), flush=True)
    lines = table(results, args.model.name) if results else []
    if args.configs or args.configs_only:
        lines += ["", "The network alone at 24^3 (onnxruntime, one thread, random weights, the Cornell box's "
                  "inputs), ProbeNet with 3 levels and a 2-layer head:", "",
                  "| config | parameters | network CPU ms (median) |", "|---|---|---|"]
        lines += [f"| {name} | {count} | {ms:.2f} |" for name, count, ms in network_configs(CONFIGS, 24, args.repeats)]
    load = os.getloadavg()[0]
    command = " ".join(["python -m viewer.bench.neural", *args.scenes, "--probes", *map(str, args.probes)]
                       + (["--voxels", *map(str, args.voxels)] if args.voxels else [])
                       + (["--configs"] if args.configs else []))
    lines += ["", f"`{command}`, {args.repeats} runs each, {time.strftime('%Y-%m-%d')}, 1-minute load average "
              f"{load:.1f} on {os.cpu_count()} cores."]
    if args.write:
        replace_block(ROOT / "docs" / "PERFORMANCE.md", MARKER, "\n".join(lines), "# Performance")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
