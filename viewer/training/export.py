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


def export_onnx(model: ProbeNet, path: Path, resolution: int) -> None:
    """`model` as an ONNX file of two inputs, the encoded inputs and the same through asinh
    (`encoding.compressed`: numpy computes it in a third of the time the ONNX operators took), in
    inference mode (its training-time sink left out) whatever mode it is in."""
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


def split_filters(path: Path) -> np.ndarray | None:
    """Move ProbeNet's seen filter out of the exported graph at `path` (rewritten in place): each grouped
    3x3x3 convolution of a replicate-padded product of encoding channels and the open share becomes a
    graph input named for the channels (`network_feed.FILTERED`), which the runtime computes
    (`network_feed.filtered`: onnxruntime has no depthwise 3D convolution), and the nodes that only fed
    it go. Returns its kernels (9, 27); None where the graph has no such convolution (left as it is)."""
    import onnx
    from onnx import helper, numpy_helper

    model = onnx.load(str(path))
    graph = model.graph
    producer = {out: node for node in graph.node for out in node.output}
    weights = {item.name: item for item in graph.initializer}
    replaced, kernels = {}, None
    for node in list(graph.node):
        if node.op_type != "Conv" or len(node.input) < 2 or node.input[1] not in weights:
            continue
        group = next((helper.get_attribute_value(a) for a in node.attribute if a.name == "group"), 1)
        weight = numpy_helper.to_array(weights[node.input[1]])
        pad = producer.get(node.input[0])
        if group != 9 or weight.shape != (9, 1, 3, 3, 3) or pad is None or pad.op_type != "Pad":
            continue
        name = _filtered_channels(producer.get(pad.input[0]), producer, weights)
        if name is not None:
            replaced[node.output[0]] = name
            graph.node.remove(node)
            kernels = weight.reshape(9, 27)
    if not replaced:
        return None
    for node in graph.node:
        for k, name in enumerate(node.input):
            node.input[k] = replaced.get(name, name)
    graph.input.extend(helper.make_tensor_value_info(name, onnx.TensorProto.FLOAT, ["passes", 9, "m", "m", "m"])
                       for name in replaced.values())
    _drop_unused(graph)
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return kernels


def _filtered_channels(product, producer: dict, weights: dict) -> str | None:
    """The `network_feed.FILTERED` name of a Mul node of a Slice of the graph's `inputs` (9 channels from
    where a FILTERED entry starts) and another factor; None if it is not one."""
    from onnx import numpy_helper

    from viewer.neural.network_feed import FILTERED

    def constant(name):
        if name in weights:
            return numpy_helper.to_array(weights[name])
        node = producer.get(name)
        if node is not None and node.op_type == "Constant":
            return numpy_helper.to_array(node.attribute[0].t)
        return None

    if product is None or product.op_type != "Mul":
        return None
    for factor in product.input:
        part = producer.get(factor)
        if part is None or part.op_type != "Slice" or part.input[0] != INPUT_NAMES[0]:
            continue
        start, stop = constant(part.input[1]), constant(part.input[2])
        for name, channels in FILTERED.items():
            if start is not None and stop is not None and (int(start[0]), int(stop[0])) == (channels.start,
                                                                                            channels.stop):
                return name
    return None


def _drop_unused(graph) -> None:
    """Remove the nodes whose outputs nothing reads, again until none is left, and the unread weights."""
    while True:
        read = {name for node in graph.node for name in node.input} | {out.name for out in graph.output}
        unused = [node for node in graph.node if not any(out in read for out in node.output)]
        if not unused:
            break
        for node in unused:
            graph.node.remove(node)
    read = {name for node in graph.node for name in node.input}
    for item in [item for item in graph.initializer if item.name not in read]:
        graph.initializer.remove(item)


INPUT_NAMES = ("inputs", "compressed")
OPSET = 18


def max_difference(model: ProbeNet, path: Path, inputs: np.ndarray) -> float:
    """Largest |onnxruntime - torch| over the outputs for the given encoded inputs, relative to the
    largest output (at least 1): float32 round-off grows with the values (outputs by a lamp reach
    hundreds of times the room's mean)."""
    import onnxruntime as ort

    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    inputs = inputs.astype(np.float32)
    compressed = encoding.compressed(inputs)   # both given the viewer's asinh: torch's differs a little
    ours = session.run(None, feed([i.name for i in session.get_inputs()], inputs, kernels(model)))[0]
    with torch.no_grad():
        theirs = model.eval()(torch.from_numpy(inputs), torch.from_numpy(compressed)).numpy()
    return float(np.abs(ours - theirs).max() / max(1.0, float(np.abs(theirs).max())))


def write_card(path: Path, model: ProbeNet, resolution: int, training: dict, metrics: dict,
               ranges: str | None = None) -> dict:
    """The card beside the .onnx file. `ranges`: the viewer.neural.ranges preset the dataset was drawn
    from (else the one `training` names), whose training domain (viewer.neural.domain) the card carries: the
    viewer warns on scenes outside it."""
    ranges = ranges or training.get("ranges")
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
            "normalization": "one pass per colour channel; emission and direct light divided by the pass's "
                             "scale (mean direct radiance DC over the probes, shadows traced), outputs multiplied by it",
            "second_input": {"name": "compressed", "features": "the same, the light through asinh: channels "
                             + ", ".join(f"{part.start}-{part.stop - 1}" for part in encoding.COMPRESSED)},
            "filtered": {"inputs": graph_filters(path),
                         "what": "the seen filter's products, which the graph takes as inputs where it lists "
                                 "them: the channels " + ", ".join(f"{name} {part.start}-{part.stop - 1}"
                                                                  for name, part in FILTERED.items())
                                 + " times the open share, each convolved with its 3x3x3 kernel, edges repeated "
                                   "(viewer.neural.network_feed)",
                         "kernels": kernels(model).tolist()},
        },
        "outputs": {"name": "probes", "channels": OUTPUTS,
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
    args = parser.parse_args(argv)
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
    inputs = encoding.encode_scene(scene, args.probes, ENCODING_VOXELS).inputs
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
