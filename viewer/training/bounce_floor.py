"""How far the encoding's bounce gather can carry the reflected light, whatever light the surfaces have.

    python -m viewer.training.bounce_floor --data data/gi-v2 --rooms 20 [--model models/probenet.onnx]
                                           [--full] [--out docs/data/bounce_floor.json]
    python -m viewer.training.bounce_floor --data DATA --rooms 20 --ladder [--split paper | --scenes SCENE ...]
                                           [--out docs/data/bounce_ladder.json]

For validation rooms of a dataset, the reflected light at the probes (the solver's, the network's
target) against three gathers of surface light the way `encoding.Bounce` gathers the one-bounce input
(patches as points, no shadows): the input itself (its direct light from the encoding's shadowed SH),
the same gather of the solver's exact direct irradiance of every voxel (one bounce), and of the
solver's converged light of every voxel (every bounce); and the seen input (viewer/neural/seen.py: two
bounces gathered by exact rays), raw and after a 3x3x3 box filter. Each is scaled by its best gain for the room
(the network learns a gain for free) and scored on the probes outside solids, relative RMSE per room.
If even the converged surface light gathered this way is far off, the error is in the gather (the
surfaces' transport to the probes), not in the surfaces' light: what the network cannot learn from
a lattice of densities. `--full` gathers 1-cell patches on the probes' own lattice; `--model` adds the
network's own reflected light (as it answers, no gain) beside.

`--ladder` gathers the same converged surface light with more and more visibility instead
(viewer/training/ladder.py: no visibility, voxel cone tracing with 6 and 16 cones, exact rays at 8 to 64
a probe), each raw and after a 3x3x3 box filter, with the milliseconds each gather takes. It needs no
full dataset: the first 20 validation rooms of `data/gi-v2` and the paper's fixed scenes are made alone,
the same rooms (without the Mitsuba probes, which no gather here reads), in about 3 minutes on two cores
by

    python -m viewer.training.dataset --out /tmp/ladder-data --train 0 --val 20 --seed 14 --ranges v2 \
        --probes 24 --truth physical --splits paper,val
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from viewer.neural import encoding
from viewer.neural.network_feed import encoding_walls
from viewer.physical.gi import GISettings, PhysicalGI
from viewer.rays.voxels import voxelize
from viewer.training import ladder

GATHERS = ("bounce input", "exact one bounce", "converged surface light", "seen input",
           "seen input, box filtered")
NETWORK = "network (as it is)"


def room_errors(example, target: np.ndarray, valid: np.ndarray, probes: int, voxels: int, full: bool,
                field=None) -> dict:
    """Best-gain relative RMSE of each gather in GATHERS against `target` (3, 9, M, M, M) radiance, and
    the network's (`field`, a viewer.neural.field.NeuralField) as it answers, without a gain."""
    scene = example.scene
    grid = voxelize(scene, voxels)
    enc = encoding.encode(grid, scene.sun, example.lo, example.hi, probes, encoding.occluders(scene, grid))
    solver = PhysicalGI(GISettings(voxels=voxels, probes=probes))
    solver.update(scene)
    if solver.geometry.voxels.count != grid.count:
        raise RuntimeError(f"{example.path}: the solver's voxels are not the encoding's")
    size = dict(patch=1, lattice=1) if full else {}
    bounce = encoding.Bounce(grid, example.lo, example.hi, probes, **size)

    def lattice(sh):  # (P, 9, 3) -> (3, 9, M, M, M)
        return sh.reshape(probes, probes, probes, 9, 3).transpose(4, 3, 0, 1, 2)

    scale = enc.scale[:, None, None, None, None]
    if full:   # the input's own gather again, on the finer patches: from the encoding's direct light
        direct_sh = (enc.inputs[:, encoding.DIRECT] * scale).transpose(2, 3, 4, 1, 0).reshape(-1, 9, 3)
        bounce_input = lattice(bounce.sh(grid.albedo, direct_sh))
    else:
        bounce_input = enc.inputs[:, encoding.BOUNCE].astype(np.float64) * scale
    seen = enc.inputs[:, encoding.SEEN].astype(np.float64) * scale
    estimates = (bounce_input, lattice(bounce.gathered(grid.albedo * solver.lighting.direct / np.pi)),
                 lattice(bounce.gathered(solver.lighting.reflected.astype(np.float64))), seen,
                 ladder.box_filtered(seen, valid))
    out = {name: ladder.best_gain_error(estimate, target, valid) for name, estimate in zip(GATHERS, estimates)}
    t = target[..., valid]
    if field is not None:
        reflected = field.run(enc.inputs.astype(np.float32), encoding_walls(enc))[:, 9:18] * scale
        out[NETWORK] = float(np.sqrt(((reflected[..., valid] - t) ** 2).sum() / max(float((t ** 2).sum()), 1e-30)))
    return out


def room_ladder(example, target: np.ndarray, valid: np.ndarray, probes: int, voxels: int) -> dict:
    """viewer.training.ladder's rungs for one room, from the solver's converged light on `voxels`^3."""
    scene = example.scene
    solver = PhysicalGI(GISettings(voxels=voxels, probes=probes))
    solver.update(scene)
    bounce = encoding.Bounce(solver.geometry.voxels, example.lo, example.hi, probes)
    return ladder.room_ladder(scene, example.lo, example.hi, target, valid, probes, solver, bounce)


def dataset_rooms(data: Path, split_name: str, rooms: int, probes: int):
    """(name, example, target (3, 9, M, M, M) reflected light, valid (M, M, M)) of a dataset split's rooms."""
    from viewer.training.dataset import load_example, room_refs
    from viewer.training.samples import load_split

    split = load_split(data, split_name, probes)
    refs = room_refs(data, split_name)
    for i in range(min(rooms, len(split))):
        target = split.targets[i].astype(np.float64)[:, 9:18] * split.scale[i][:, None, None, None, None]
        yield split.names[i], load_example(refs[i]), target, np.asarray(split.valid[i], bool)


def scene_rooms(sources: list[str], probes: int):
    """The same for scenes outside a dataset (a built-in name or a file): their target made as the dataset
    makes it (viewer.training.truth's physical solver on 32^3 voxels, 256 directions a probe)."""
    from types import SimpleNamespace

    from viewer.scene import load
    from viewer.training.truth import physical_sh

    for source in sources:
        scene = load(source)
        lo, hi = scene.bounds
        total, direct, valid, _ = physical_sh(scene, [probes])[probes]
        target = (np.asarray(total, np.float64) - direct).transpose(4, 3, 0, 1, 2)
        yield scene.name, SimpleNamespace(scene=scene, lo=lo, hi=hi, path=source), target, np.asarray(valid, bool)


def main(argv=None) -> int:
    from viewer.cli_parsing import add_data, add_out, tool_parser
    from viewer.training.samples import ENCODING_VOXELS

    parser = tool_parser(__doc__, prog="python -m viewer.training.bounce_floor")
    add_data(parser)
    parser.add_argument("--rooms", type=int, default=20)
    parser.add_argument("--split", choices=("val", "paper"), default="val",
                        help="the dataset's validation rooms (default) or its fixed paper scenes")
    parser.add_argument("--probes", type=int, default=24)
    parser.add_argument("--full", action="store_true", help="1-cell patches on the probes' own lattice")
    parser.add_argument("--ladder", action="store_true",
                        help="the visibility ladder: cone traced and ray-cast gathers (viewer/training/ladder.py)")
    parser.add_argument("--scenes", nargs="+", metavar="SCENE",
                        help="instead of the dataset: these scenes (built-in names or files), their targets made "
                             "as the dataset's")
    parser.add_argument("--model", type=Path, help="also the network's reflected light (an .onnx with its card)")
    add_out(parser, help="JSON file for the per-room errors")
    args = parser.parse_args(argv)
    field = None
    if args.model:
        from viewer.neural.field import NeuralField

        field = NeuralField(args.model)
    rows = []
    for name, example, target, valid in (scene_rooms(args.scenes, args.probes) if args.scenes else
                                         dataset_rooms(args.data, args.split, args.rooms, args.probes)):
        if args.ladder:
            rows.append({"room": name, "ladder": room_ladder(example, target, valid, args.probes, ENCODING_VOXELS)})
            print(name + "  " + "  ".join(f"{k}: {100 * v['raw']:.1f}% / {100 * v['filtered']:.1f}%"
                                          for k, v in rows[-1]["ladder"].items()), file=sys.stderr)
            continue
        errors = room_errors(example, target, valid, args.probes, ENCODING_VOXELS, args.full, field)
        rows.append({"room": name, **errors})
        print(f"{name}  " + "  ".join(f"{k} {100 * v:.1f}%" for k, v in errors.items()), file=sys.stderr)
    command = " ".join(["python -m viewer.training.bounce_floor", *(sys.argv[1:] if argv is None else argv)])
    if args.ladder:
        text, summary = ladder.table(rows)
        print(text)
        if args.out:
            manifest = args.data / "manifest.json"   # how the rooms were made
            made = (json.loads(manifest.read_text()).get("commands") if manifest.exists() and not args.scenes
                    else None)
            args.out.write_text(json.dumps({"command": command, "dataset": made, "rooms": rows, "summary": summary},
                                           indent=1) + "\n")
        return 0
    names = GATHERS + ((NETWORK,) if field is not None else ())
    medians = {k: float(np.median([r[k] for r in rows])) for k in names}
    print("| gather of the surface light (best gain a room) | median rel. RMSE | worst |\n|---|---|---|")
    for k in names:
        print(f"| {k} | {100 * medians[k]:.1f}% | {100 * max(r[k] for r in rows):.1f}% |")
    if args.out:
        args.out.write_text(json.dumps({"command": command, "rooms": rows, "median": medians}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
