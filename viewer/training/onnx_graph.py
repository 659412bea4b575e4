"""Surgery on an exported ProbeNet's ONNX graph: what the runtime computes faster outside it is taken out.

- `split_filters`: the seen filter's grouped 3x3x3 convolutions (onnxruntime has no depthwise 3D path)
  become graph inputs, computed by viewer.neural.network_feed.
- `split_tail`: the graph ends at the head; the arithmetic after it runs in one compiled pass
  (viewer.neural.network_tail).

Both rewrite the file in place and leave a graph without what they look for as it is.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from viewer.neural.field import OUTPUTS
from viewer.neural.network_tail import HEAD, Tail

ENCODED = "inputs"
"""The graph's input of the encoded features (viewer.training.export.INPUT_NAMES' first)."""


def split_tail(path: Path) -> Tail | None:
    """Cut the graph at `path` (rewritten in place) after ProbeNet's head: its output becomes the head's
    19 channels (`network_tail.HEAD`), and the arithmetic after it, which onnxruntime runs a pass per
    operator, is left to `network_tail.Tail.probes` (one compiled pass). The graph's inputs that only
    that arithmetic read go with it. Returns the two learned gains it read, for the card; None where the
    graph has no such head and gains (left as it is)."""
    import onnx
    from onnx import helper, numpy_helper

    model = onnx.load(str(path))
    graph = model.graph
    weights = {item.name: numpy_helper.to_array(item) for item in graph.initializer}
    heads = [node for node in graph.node if node.op_type == "Conv" and node.name.startswith("/head/")]
    if not heads or "bounce_gain" not in weights or "seen_gain" not in weights:
        return None
    tail = Tail(float(weights["bounce_gain"]), float(weights["seen_gain"]))
    heads[-1].output[0] = HEAD   # the graph's output; the nodes after it go below, as nothing reads them
    del graph.output[:]
    graph.output.append(helper.make_tensor_value_info(HEAD, onnx.TensorProto.FLOAT, ["passes", OUTPUTS, "m", "m", "m"]))
    _drop_unused(graph)
    read = {name for node in graph.node for name in node.input}
    for item in [item for item in graph.input if item.name not in read]:
        graph.input.remove(item)
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return tail


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
        if part is None or part.op_type != "Slice" or part.input[0] != ENCODED:
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
