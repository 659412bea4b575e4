"""The network's seen filter computed outside its graph (viewer/neural/network_feed.py) and the export that
moves it there (viewer.training.onnx_graph.split_filters): the same numbers as the graph's own filter."""

import numpy as np
import pytest

from viewer.neural import encoding
from viewer.neural.network_feed import FILTERED, feed, filtered

torch = pytest.importorskip("torch")
onnx = pytest.importorskip("onnx")
from viewer.training import export  # noqa: E402 - needs torch
from viewer.training.models import ProbeNet, ProbeNetConfig  # noqa: E402


@pytest.mark.parametrize("name", list(FILTERED))
def test_the_filter_is_the_grouped_convolution_with_repeated_edges(name):
    rng = np.random.default_rng(1)
    inputs = rng.normal(size=(2, encoding.CHANNELS, 7, 7, 7)).astype(np.float32)
    inputs[:, encoding.OPEN] = rng.random((2, 7, 7, 7))
    kernels = rng.normal(size=(9, 27)).astype(np.float32)
    conv = torch.nn.Conv3d(9, 9, 3, padding=1, padding_mode="replicate", groups=9, bias=False)
    conv.weight.data = torch.from_numpy(kernels.reshape(9, 1, 3, 3, 3))
    x = torch.from_numpy(inputs)
    expected = conv(x[:, FILTERED[name]] * x[:, encoding.OPEN:encoding.OPEN + 1]).detach().numpy()
    np.testing.assert_allclose(filtered(inputs, FILTERED[name], kernels), expected, rtol=1e-5, atol=1e-5)
    fed = feed(["inputs", "compressed", name], inputs, kernels)
    assert list(fed) == ["inputs", "compressed", name] and fed["inputs"] is inputs
    with pytest.raises(ValueError, match="kernels"):
        feed(["inputs", name], inputs, None)


def test_the_export_takes_the_filter_out_of_the_graph_and_keeps_the_output(tmp_path):
    torch.manual_seed(0)
    model = ProbeNet(ProbeNetConfig(width=4, hidden=8, levels=2)).eval()
    with torch.no_grad():   # a filter unlike the box it starts as, so that its kernels must travel
        model.seen_filter.weight.uniform_(-0.2, 0.3)
    path = tmp_path / "split.onnx"
    export.export_onnx(model, path, 8, tail=False)   # the whole graph: the tail's cut is tested on its own
    graph = onnx.load(str(path)).graph
    assert [i.name for i in graph.input] == ["inputs", "compressed", "seen_filtered", "bounce_filtered"]
    assert not [n for n in graph.node if n.op_type == "Conv" and any(a.name == "group" and a.i == 9
                                                                       for a in n.attribute)]
    assert "seen_filter.weight" not in {i.name for i in graph.initializer}
    np.testing.assert_array_equal(export.kernels(model),
                                  model.seen_filter.weight.detach().numpy().reshape(9, 27))
    inputs = encoding.encode_scene(encoding_scene(), 8, 16).inputs
    assert export.max_difference(model, path, inputs) < 1e-5
    assert export.split_filters(path) is None   # nothing left to split: the file stays as it is


def encoding_scene():
    from viewer.scene import load

    return load("cornell")
