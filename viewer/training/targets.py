"""Which training targets to make: Mitsuba at few directions per probe, or the physical solver.

    python -m viewer.training.targets --rooms 20 --probes 24,16 --low 16,64 --truth-directions 1024 \
        --out docs/data/targets.json

On freshly drawn validation rooms (`dataset.make_scene("val", i, seed, ranges)`), each candidate's probe
SH is compared with a Mitsuba truth at `--truth-directions` directions per probe: relative RMSE over the
probes outside solids (the physical geometry's back-face rule) and all 27 numbers of a probe, for all the
light and for the reflected (indirect) part, the one the renderer shades from its probes.

A noisy but unbiased target (Mitsuba at 16 or 64 directions) averages out over the rooms of a dataset,
the solver's bias does not. Each low-direction Mitsuba run is made twice with independent seeds: with
e1 the error of one run and e2 that of the mean of the two, noise and bias separate as
e_K^2 = b^2 + s^2 / K, so b^2 = 2 e2^2 - e1^2 (the part that averaging K runs, or K rooms, never removes).
For an unbiased estimator b is the truth's own noise (the floor every candidate is measured against);
the solver's bias is then sqrt(e^2 - floor^2). Seconds are wall-clock per room on this machine.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from viewer.probes.grid import ProbeGrid
from viewer.training import dataset, truth


def relative_rmse(estimate: np.ndarray, reference: np.ndarray, valid: np.ndarray) -> float:
    """sqrt(sum (estimate - reference)^2 / sum reference^2) over the valid probes' 27 numbers."""
    e, r = estimate[valid], reference[valid]
    return float(np.sqrt(np.sum((e - r) ** 2) / max(np.sum(r ** 2), 1e-30)))


def mitsuba_parts(scene, resolution: int, directions: int, seed: int):
    """(total, reflected) (M, M, M, 9, 3) and seconds."""
    from viewer.reference import mitsuba as reference

    lo, hi = scene.bounds
    points = ProbeGrid.positions_for(lo, hi, resolution).reshape(-1, 3)
    clock = time.perf_counter()
    reflected, direct = reference.probe_sh_parts(scene, points, directions=directions, seed=seed)
    seconds = time.perf_counter() - clock
    shape = (resolution,) * 3 + (9, 3)
    return (reflected + direct).reshape(shape), reflected.reshape(shape), seconds


def measure_room(scene, resolutions, low, truth_directions: int, seed: int) -> dict:
    """Errors and seconds of every candidate on one room, per probe resolution."""
    out = {}
    for m in resolutions:
        clock = time.perf_counter()
        total_p, direct_p, valid, _ = truth.physical_sh(scene, (m,))[m]
        physical_seconds = time.perf_counter() - clock
        total_t, reflected_t, truth_seconds = mitsuba_parts(scene, m, truth_directions, seed)
        row = {"physical": {"all": relative_rmse(total_p, total_t, valid),
                            "indirect": relative_rmse(total_p - direct_p, reflected_t, valid),
                            "seconds": physical_seconds},
               "truth_seconds": truth_seconds, "valid": int(valid.sum())}
        for d in low:
            runs = [mitsuba_parts(scene, m, d, seed + 1 + k) for k in range(2)]
            mean_total = 0.5 * (runs[0][0] + runs[1][0])
            mean_reflected = 0.5 * (runs[0][1] + runs[1][1])
            row[f"mitsuba-{d}"] = {
                "all": relative_rmse(runs[0][0], total_t, valid),
                "indirect": relative_rmse(runs[0][1], reflected_t, valid),
                "all_mean2": relative_rmse(mean_total, total_t, valid),
                "indirect_mean2": relative_rmse(mean_reflected, reflected_t, valid),
                "seconds": float(np.mean([r[2] for r in runs]))}
        out[str(m)] = row
    return out


def summary(rooms: list[dict], resolution: str, low, truth_directions: int) -> list[dict]:
    """One row per candidate: mean, median and worst per-room error, and the error that averaging over
    rooms leaves ('left').

    Mitsuba at K directions is unbiased: what averaging leaves is 0, and its noise falls as 1/sqrt(K)
    (checked: `noise_ratio`, the error of one run over that of the mean of two, is sqrt(2) for pure
    noise). The truth at T directions has the same noise / sqrt(T / K), so with e the error of the run
    at the most directions K, the truth's own noise in a room is e / sqrt(T / K + 1), and the solver's
    bias in that room is sqrt(e_solver^2 - truth noise^2). Heavy tails (fireflies near emitters, in the
    light straight from them) break the 1/sqrt(K) law; the rows say where (`noise_ratio` far from
    1.41)."""
    rows = [r[resolution] for r in rooms]
    most = f"mitsuba-{max(low)}"
    out = []
    for d in low:
        name = f"mitsuba-{d}"
        entry = {"target": f"Mitsuba, {d} directions", "seconds": float(np.mean([r[name]["seconds"] for r in rows]))}
        for part in ("all", "indirect"):
            e1 = np.array([r[name][part] for r in rows])
            e2 = np.array([r[name][f"{part}_mean2"] for r in rows])
            entry.update({f"{part}_mean": float(e1.mean()), f"{part}_median": float(np.median(e1)),
                          f"{part}_worst": float(e1.max()), f"{part}_left": 0.0,
                          f"{part}_noise_ratio": float(np.median(e1 / e2))})
        out.append(entry)
    entry = {"target": "physical solver", "seconds": float(np.mean([r["physical"]["seconds"] for r in rows]))}
    for part in ("all", "indirect"):
        e = np.array([r["physical"][part] for r in rows])
        floor = np.array([r[most][part] for r in rows]) / np.sqrt(truth_directions / max(low) + 1)
        bias = np.sqrt(np.maximum(e ** 2 - floor ** 2, 0.0))
        entry.update({f"{part}_mean": float(e.mean()), f"{part}_median": float(np.median(e)),
                      f"{part}_worst": float(e.max()), f"{part}_left": float(bias.mean()),
                      f"{part}_left_median": float(np.median(bias)), f"{part}_truth_noise": float(floor.mean())})
    out.append(entry)
    return out


def table(rows: list[dict], resolution: str, rooms: int, truth_directions: int) -> str:
    lines = [f"{resolution}^3 probes, {rooms} rooms, against Mitsuba at {truth_directions} directions: relative "
             "RMSE per room, mean / median / worst; 'left': what averaging over rooms leaves (the bias, mean "
             "over rooms); s / room: one room's probes at this resolution, wall clock, two threads",
             "",
             "| target | all light | all, left | indirect | indirect, left | s / room |",
             "| --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        cells = [r["target"]]
        for part in ("all", "indirect"):
            cells += [f"{100 * r[f'{part}_mean']:.0f}% / {100 * r[f'{part}_median']:.0f}% / "
                      f"{100 * r[f'{part}_worst']:.0f}%", f"{100 * r[f'{part}_left']:.0f}%"]
        cells.append(f"{r['seconds']:.2f}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    from viewer.cli_parsing import add_out, tool_parser

    p = tool_parser(__doc__, prog="python -m viewer.training.targets")
    p.add_argument("--rooms", type=int, default=20, help="validation rooms measured (default 20)")
    p.add_argument("--seed", type=int, default=14, help="dataset seed the rooms are drawn with (default 14)")
    p.add_argument("--ranges", default="v2", help="procedural ranges preset (default v2)")
    p.add_argument("--probes", default="24,16", help="probe resolutions (default 24,16)")
    p.add_argument("--low", default="16,64", help="Mitsuba directions per probe of the candidates (default 16,64)")
    p.add_argument("--truth-directions", type=int, default=1024, help="Mitsuba directions of the truth")
    add_out(p, Path("docs/data/targets.json"))
    p.add_argument("--tables-only", action="store_true", help="print the tables of --out again, measuring nothing")
    args = p.parse_args(argv)
    resolutions = [int(v) for v in args.probes.split(",")]
    low = [int(v) for v in args.low.split(",")]
    if args.tables_only:
        saved = json.loads(args.out.read_text())
        for m in resolutions:
            rows = summary(saved["rooms"], str(m), low, args.truth_directions)
            print(table(rows, str(m), len(saved["rooms"]), args.truth_directions) + "\n")
        return 0
    rooms = []
    for i in range(args.rooms):
        scene, _ = dataset.make_scene("val", i, args.seed, args.ranges)
        rooms.append(measure_room(scene, resolutions, low, args.truth_directions, seed=1000 + 7 * i))
        print(f"room {i + 1}/{args.rooms}: " + ", ".join(
            f"{m}^3 physical {100 * rooms[-1][str(m)]['physical']['all']:.1f}% / "
            f"{100 * rooms[-1][str(m)]['physical']['indirect']:.1f}%" for m in resolutions), file=sys.stderr, flush=True)
    tables = {str(m): summary(rooms, str(m), low, args.truth_directions) for m in resolutions}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"command": " ".join(["python -m viewer.training.targets", *(argv or sys.argv[1:])]),
                                    "rooms": rooms, "summary": tables}, indent=1) + "\n")
    for m in resolutions:
        print(table(tables[str(m)], str(m), args.rooms, args.truth_directions) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
