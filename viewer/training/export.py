"""A trained ProbeNet -> `models/<name>.onnx` + its JSON card (what `viewer.neural.field` loads).

    python -m viewer.training.export runs/probenet --name probenet [--out models]

The export is checked before the card is written: onnxruntime's output must equal PyTorch's within
1e-4 on a real encoded scene.
"""

from __future__ import annotations

import json
import platform
import sys
import warnings
from pathlib import Path

import numpy as np
import torch

from viewer.neural import encoding
from viewer.neural.domain import Domain
from viewer.neural.field import OUTPUTS, file_sha256
from viewer.neural.network_feed import FILTERED, feed
from viewer.neural.network_tail import HEAD, Tail, fed_names, run_graph
from viewer.training.onnx_graph import split_filters, split_tail
from viewer.training.models import ProbeNet, ProbeNetConfig, parameter_count
from viewer.training.samples import ENCODING_VOXELS

ROOT = Path(__file__).resolve().parents[2]
TOLERANCE = 1e-5


def shipped_checkpoint(run: Path) -> Path:
    """The run's best epoch (`train.BEST`) where it kept one, else its latest."""
    from viewer.training.train import BEST

    best = Path(run) / BEST
    return best if best.exists() else Path(run) / "checkpoint.pt"


def load_run(run: Path) -> ProbeNet:
    state = torch.load(shipped_checkpoint(run), weights_only=False)
    model = ProbeNet(ProbeNetConfig(**state["config"]))
    model.load_state_dict(state["model"])
    return model.eval()


def export_onnx(model: ProbeNet, path: Path, resolution: int, tail: bool = True) -> None:
    """`model` as an ONNX file of two inputs, the encoded inputs and the same through asinh
    (`encoding.compressed`: numpy computes it in a third of the time the ONNX operators took), in
    inference mode (its training-time sink left out) whatever mode it is in; its seen filter taken out
    of the graph (`split_filters`) and, with `tail`, the graph cut after its head (`split_tail`)."""
    model = model.eval()
    example = torch.zeros(3, encoding.CHANNELS, resolution, resolution, resolution)
    path.parent.mkdir(parents=True, exist_ok=True)
    lattice = {0: "passes", 2: "m", 3: "m", 4: "m"}
    # The TorchScript exporter: torch 2.13's default (dynamo) exporter fails on this model ("references
    # nonexistent attribute weight"), and the legacy one's graph matches torch within 1e-6. Operator set
    # 18, not the exporter's 20: onnxruntime runs AveragePool of set 19 on (the one with dilations) 14x
    # slower, 1.1 ms of the network's 13.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(model, (example, example), str(path), input_names=list(INPUT_NAMES),
                          output_names=["probes"], dynamo=False, opset_version=OPSET,
                          dynamic_axes={**{name: lattice for name in INPUT_NAMES}, "probes": lattice})
    split_filters(path)
    if tail:
        split_tail(path)


def network_output(path: Path, inputs: np.ndarray, kernels: np.ndarray, tail: Tail | None) -> np.ndarray:
    """The exported network at `path` on encoded `inputs` as the viewer runs it (viewer.neural.field): its
    feed, and the `tail` where its graph ends at its head."""
    import onnxruntime as ort

    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    return run_graph(session, feed(fed_names([i.name for i in session.get_inputs()], tail), inputs, kernels), tail)


def model_tail(model: ProbeNet) -> Tail:
    """The gains `split_tail` reads from an export of `model`."""
    return Tail(float(model.bounce_gain.detach()), float(model.seen_gain.detach()))


INPUT_NAMES = ("inputs", "compressed")
OPSET = 18


def max_difference(model: ProbeNet, path: Path, inputs: np.ndarray) -> float:
    """Largest |onnxruntime - torch| over the outputs for the given encoded inputs, relative to the
    largest output (at least 1): float32 round-off grows with the values (outputs by a lamp reach
    hundreds of times the room's mean)."""
    inputs = inputs.astype(np.float32)
    compressed = encoding.compressed(inputs)   # both given the viewer's asinh: torch's differs a little
    tail = model_tail(model) if graph_output(path) == HEAD else None
    ours = network_output(path, inputs, kernels(model), tail)
    with torch.no_grad():
        theirs = model.eval()(torch.from_numpy(inputs), torch.from_numpy(compressed)).numpy()
    return float(np.abs(ours - theirs).max() / max(1.0, float(np.abs(theirs).max())))


def write_card(path: Path, model: ProbeNet, resolution: int, training: dict, metrics: dict,
               ranges: str | None = None) -> dict:
    """The card beside the .onnx file. `ranges`: the viewer.neural.ranges preset the dataset was drawn
    from (else the one `training` names), whose training domain (viewer.neural.domain) the card carries: the
    viewer warns on scenes outside it."""
    ranges = ranges or training.get("ranges")
    output = graph_output(path)
    card = {
        "name": path.stem,
        "file": path.name,
        "sha256": file_sha256(path),
        "architecture": {"family": "ProbeNet", **model.config.to_dict()},
        "parameters": parameter_count(model),
        "precision": "float32",
        "inputs": {
            "name": "inputs", "shape": ["3 x scenes", encoding.CHANNELS, resolution, resolution, resolution],
            "features": list(encoding.FEATURES), "encoding_version": encoding.VERSION, "voxels": ENCODING_VOXELS,
            "seen_rays": encoding.SEEN_RAYS, "direct_shadows": encoding.DIRECT_SHADOWS,
            "normalization": "one pass per colour channel; emission and direct light divided by the pass's "
                             "scale (mean direct radiance DC over the probes, "
                             + ("shadows traced" if encoding.DIRECT_SHADOWS else "without the probes' shadows")
                             + "), outputs multiplied by it",
            "second_input": {"name": "compressed", "features": "the same, the light through asinh: channels "
                             + ", ".join(f"{part.start}-{part.stop - 1}" for part in encoding.COMPRESSED)},
            "filtered": {"inputs": list(FILTERED) if output == HEAD else graph_filters(path),
                         "what": "the seen filter's products, which the graph (or its tail) reads where it lists "
                                 "them: the channels " + ", ".join(f"{name} {part.start}-{part.stop - 1}"
                                                                  for name, part in FILTERED.items())
                                 + " times the open share, each convolved with its 3x3x3 kernel, edges repeated "
                                   "(viewer.neural.network_feed)",
                         "kernels": kernels(model).tolist()},
        },
        **({"tail": model_tail(model).to_dict()} if output == HEAD else {}),
        "outputs": {"name": output, "channels": OUTPUTS,
                    "tail": "where the name is head, the graph ends at ProbeNet's head and the card's tail gains "
                            "finish it (viewer.neural.network_tail)",
                    "layout": "0-8 SH of all incident light, 9-17 SH of the light reflected by surfaces, "
                              "18 validity logit (> 0: outside solid geometry)"},
        "probes": {"resolution": resolution, "runs_at": "any M divisible by 2^levels (trained at resolution)", "box": "scene bounds", "centres": "lo + (i + 0.5) (hi - lo) / M",
                   "sh_order": "00, 1-1, 10, 11, 2-2, 2-1, 20, 21, 22 (docs/ARCHITECTURE.md)", "index": "[x, y, z]"},
        "training": training,
        **({"domain": Domain.from_preset(ranges).to_dict()} if ranges else {}),
        "metrics": metrics,
        "exported_with": {"torch": torch.__version__, "python": platform.python_version()},
    }
    path.with_suffix(".json").write_text(json.dumps(card, indent=1) + "\n")
    return card


def kernels(model: ProbeNet) -> np.ndarray:
    """(9, 27) float32 the seen filter's kernels, as the card carries them."""
    return model.seen_filter.weight.detach().numpy().reshape(9, 27).astype(np.float32)


def graph_output(path: Path) -> str:
    """The name of the graph's output: `network_tail.HEAD` where `split_tail` cut it."""
    import onnxruntime as ort

    return ort.InferenceSession(str(path), providers=["CPUExecutionProvider"]).get_outputs()[0].name


def graph_filters(path: Path) -> list[str]:
    """The `network_feed.FILTERED` inputs the graph at `path` takes."""
    import onnxruntime as ort

    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    return [i.name for i in session.get_inputs() if i.name in FILTERED]


def export(run: Path, out: Path, resolution: int, inputs: np.ndarray, training: dict, metrics: dict,
           ranges: str | None = None) -> dict:
    model = load_run(run)
    export_onnx(model, out, resolution)
    difference = max_difference(model, out, inputs)
    if difference > TOLERANCE:
        raise RuntimeError(f"onnxruntime differs from torch by {difference:.2e} of the largest output (> {TOLERANCE})")
    return write_card(out, model, resolution, training, {**metrics, "onnx_relative_difference": difference}, ranges)


def read_back(path: Path) -> ProbeNet:
    """The ProbeNet an exported network holds, its weights read back from the ONNX file at `path` and
    its card (the seen filter's kernels, which the graph leaves to its feed; the global code's matrix,
    which the exporter stores transposed): the start of a fine-tune of a network whose training run is
    gone. Checked against onnxruntime as an export is."""
    import onnx
    from onnx import numpy_helper

    from viewer.scene import load

    card = json.loads(Path(path).with_suffix(".json").read_text())
    model = ProbeNet(ProbeNetConfig(**{k: v for k, v in card["architecture"].items() if k != "family"}))
    stored = {i.name: numpy_helper.to_array(i) for i in onnx.load(str(path)).graph.initializer}
    unnamed = [a for name, a in stored.items() if name not in model.state_dict()]
    state = {}
    for name, value in model.state_dict().items():
        if name in stored:
            array = stored[name]
        elif name == "seen_filter.weight":
            array = np.asarray(card["inputs"]["filtered"]["kernels"], np.float32).reshape(value.shape)
        elif name in card.get("tail", {}):   # a gain of the arithmetic cut off after the head (`split_tail`)
            array = np.asarray(card["tail"][name], np.float32).reshape(value.shape)
        else:   # a Linear's weight, stored transposed as a MatMul's operand
            matches = [a.T for a in unnamed if a.T.shape == tuple(value.shape)]
            if len(matches) != 1:
                raise ValueError(f"{path}: no single weight of shape {tuple(value.shape)} for {name}")
            array = matches[0]
        state[name] = torch.from_numpy(np.array(array, np.float32))
    model.load_state_dict(state)
    inputs = encoding.encode_scene(load("paper-test"), 8, 8).inputs
    difference = max_difference(model, Path(path), inputs)
    if difference > TOLERANCE:
        raise ValueError(f"{path}: the weights read back differ from onnxruntime by {difference:.2e}")
    return model.eval()


def cut_exported(path: Path) -> float:
    """`split_tail` on an exported network at `path` whose card is beside it: the file cut in place, its card
    given the tail's gains and the file's new sha256; checked as an export is (the file restored where the
    cut graph and its tail differ from the whole). Returns the largest difference, relative to the
    largest output; ValueError where there is nothing to cut."""
    from viewer.scene import load

    card_path = Path(path).with_suffix(".json")
    card, whole = json.loads(card_path.read_text()), Path(path).read_bytes()
    kernels = np.asarray(card["inputs"]["filtered"]["kernels"], np.float32).reshape(9, 27)
    inputs = encoding.encode_scene(load("paper-test"), 8, 8).inputs
    before = network_output(path, inputs, kernels, None)
    tail = split_tail(path)
    if tail is None:
        raise ValueError(f"{path}: no head and gains to cut after (cut already, or not a ProbeNet)")
    difference = float(np.abs(network_output(path, inputs, kernels, tail) - before).max()
                       / max(1.0, float(np.abs(before).max())))
    if difference > TOLERANCE:
        Path(path).write_bytes(whole)
        raise ValueError(f"{path}: the cut graph and its tail differ from the whole by {difference:.2e}")
    card.update(tail=tail.to_dict(), sha256=file_sha256(path))
    card["outputs"]["name"] = HEAD
    card["inputs"]["filtered"]["inputs"] = list(FILTERED)
    card.setdefault("metrics", {})["tail_relative_difference"] = difference
    card_path.write_text(json.dumps(card, indent=1) + "\n")
    return difference


def main(argv=None) -> int:
    from viewer.cli_parsing import add_out, tool_parser
    from viewer.scene import load

    parser = tool_parser(__doc__, prog="python -m viewer.training.export")
    parser.add_argument("run", type=Path)
    parser.add_argument("--name", default="probenet")
    add_out(parser, ROOT / "models")
    parser.add_argument("--probes", type=int, default=24)
    parser.add_argument("--metrics", type=Path, help="JSON of measured metrics to put on the card")
    parser.add_argument("--read-back", action="store_true",
                        help="the other way: `run` is an exported .onnx file (its card beside it), whose weights "
                             "go to --out as a run's checkpoint, the start of `train --init`")
    parser.add_argument("--split-tail", action="store_true",
                        help="`run` is an exported .onnx file (its card beside it), whose graph is cut after its "
                             "head in place: the arithmetic after it runs in one compiled pass (the same output)")
    args = parser.parse_args(argv)
    if args.split_tail:
        if not args.run.is_file() or not args.run.with_suffix(".json").is_file():
            parser.error(f"{args.run}: no exported network with its card beside it")
        try:
            difference = cut_exported(args.run)
        except ValueError as exc:
            parser.error(str(exc))
        print(f"cut {args.run} after its head (the tail's output vs the whole graph's: {difference:.1e})",
              file=sys.stderr)
        return 0
    if args.read_back:
        if not args.run.is_file() or not args.run.with_suffix(".json").is_file():
            parser.error(f"{args.run}: no exported network with its card beside it")
        model = read_back(args.run)
        args.out.mkdir(parents=True, exist_ok=True)
        torch.save({"model": model.state_dict(), "history": {"epochs": []}, "config": model.config.to_dict(),
                    "read_back_from": str(args.run), "sha256": file_sha256(args.run)}, args.out / "best.pt")
        print(f"wrote {args.out / 'best.pt'} from {args.run}", file=sys.stderr)
        return 0
    scene = load("paper-test")
    inputs = encoding.encode_scene(scene, args.probes, ENCODING_VOXELS, direct_shadows=encoding.DIRECT_SHADOWS).inputs
    history = json.loads((args.run / "history.json").read_text())
    metrics = json.loads(args.metrics.read_text()) if args.metrics else {}
    data = json.loads((args.run / "data.json").read_text()) if (args.run / "data.json").exists() else {}
    chosen = torch.load(shipped_checkpoint(args.run), weights_only=False)["history"]
    epoch = len(chosen["epochs"]) - 1   # the shipped epoch's own validation (the best, or the last)
    training = {"run": str(args.run), "epochs": len(history["epochs"]), "shipped_epoch": epoch + 1, **data}
    if epoch >= 0:   # else an untrained run (`train --epochs 0`): the network as it starts
        training.update(final_val_relative_rmse=history["val_relative_rmse"][epoch],
                        **({"final_val": history["val_metrics"][epoch]} if history.get("val_metrics") else {}))
    card = export(args.run, args.out / f"{args.name}.onnx", args.probes, inputs, training, metrics)
    print(f"wrote {args.out / args.name}.onnx ({card['parameters']} parameters, "
          f"onnx vs torch {card['metrics']['onnx_relative_difference']:.1e})", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
