"""The network's graph cut after its head (viewer.training.onnx_graph.split_tail) and finished by one compiled
pass (viewer/neural/network_tail.py): the numbers of the whole graph, and of the PyTorch model."""

import json

import numpy as np
import pytest

from viewer.neural import encoding
from viewer.neural.network_feed import encoding_walls, feed
from viewer.neural.network_tail import HEAD, fed_names, run_graph

torch = pytest.importorskip("torch")
onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")
from viewer.neural import field as neural  # noqa: E402
from viewer.training import export  # noqa: E402 - needs torch
from viewer.training.models import ProbeNet, ProbeNetConfig  # noqa: E402


def random_model(bounce_gain: float = 0.3, seen_gain: float = 0.8) -> ProbeNet:
    """A small ProbeNet whose every weight is random, its gains and filter unlike where training starts."""
    torch.manual_seed(3)
    model = ProbeNet(ProbeNetConfig(width=4, hidden=8, levels=2)).eval()
    with torch.no_grad():
        for p in model.parameters():
            p.normal_(0.0, 0.3)
        model.seen_filter.weight.uniform_(-0.1, 0.2)
        model.bounce_gain.fill_(bounce_gain)
        model.seen_gain.fill_(seen_gain)
    return model


def random_inputs(seed: int = 1, passes: int = 3, m: int = 8) -> np.ndarray:
    """Inputs that reach every branch of the tail: negative light, open shares of 0 (the 1/27 floor), an
    unshadowed DC below the detail gain's floor and seen light far above it (its clip at DETAIL_MAX)."""
    rng = np.random.default_rng(seed)
    inputs = rng.normal(size=(passes, encoding.CHANNELS, m, m, m)).astype(np.float32)
    inputs[:, encoding.OPEN] = rng.random((passes, m, m, m)) * (rng.random((passes, m, m, m)) > 0.2)
    inputs[:, encoding.BOUNCE.start, :2] = 1e-6
    inputs[:, encoding.SEEN, :2] = np.abs(inputs[:, encoding.SEEN, :2]) * 50.0
    return inputs


def graphs(tmp_path, model: ProbeNet):
    """The model exported whole and cut after its head."""
    whole, cut = tmp_path / "whole.onnx", tmp_path / "cut.onnx"
    export.export_onnx(model, whole, 8, tail=False)
    export.export_onnx(model, cut, 8)
    return whole, cut


def test_the_cut_graph_and_its_tail_give_the_whole_graphs_output(tmp_path):
    model = random_model()
    whole, cut = graphs(tmp_path, model)
    graph = onnx.load(str(cut)).graph
    assert [i.name for i in graph.input] == ["compressed"] and [o.name for o in graph.output] == [HEAD]
    assert {"bounce_gain", "seen_gain"}.isdisjoint(i.name for i in graph.initializer)
    tail = export.model_tail(model)
    assert (tail.bounce_gain, tail.seen_gain) == pytest.approx((0.3, 0.8))
    inputs = random_inputs()
    kernels = export.kernels(model)
    expected = export.network_output(whole, inputs, kernels, None)
    got = export.network_output(cut, inputs, kernels, tail)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6 * scale)
    assert export.max_difference(model, cut, inputs) < 1e-5   # against PyTorch too
    # a wrong gain is seen: the test can fail
    wrong = export.Tail(tail.bounce_gain + 0.01, tail.seen_gain)
    assert not np.allclose(export.network_output(cut, inputs, kernels, wrong), expected, rtol=1e-5, atol=1e-6 * scale)


def test_the_tail_reads_the_filter_stopped_at_walls_as_the_whole_graph_does(tmp_path):
    """The viewer's seen filter stops at walls (its products are the feed's): cut or whole, the graph's
    output is the same on a scene with walls."""
    from viewer.scene import load

    model = random_model(0.05, 1.1)
    whole, cut = graphs(tmp_path, model)
    enc = encoding.encode_scene(load("cornell"), 8, 16)
    walls = encoding_walls(enc)
    assert walls is not None and len(walls.rows)
    out = {}
    for path, tail in ((whole, None), (cut, export.model_tail(model))):
        session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        names = fed_names([i.name for i in session.get_inputs()], tail)
        out[path] = run_graph(session, feed(names, enc.inputs, export.kernels(model), walls), tail)
    np.testing.assert_allclose(out[cut], out[whole], rtol=1e-5, atol=1e-6 * np.abs(out[whole]).max())


def test_the_field_runs_a_cut_graph_with_its_cards_gains_and_refuses_one_without(tmp_path):
    model = random_model()
    whole, cut = graphs(tmp_path, model)
    for path in (whole, cut):
        export.write_card(path, model, 8, training={"note": "random weights, for tests"}, metrics={})
        card = json.loads(path.with_suffix(".json").read_text())
        card["inputs"]["voxels"] = 16
        path.with_suffix(".json").write_text(json.dumps(card))
    assert "tail" in json.loads(cut.with_suffix(".json").read_text())
    assert "tail" not in json.loads(whole.with_suffix(".json").read_text())
    a, b = neural.NeuralField(whole), neural.NeuralField(cut)
    assert a.tail is None and b.tail is not None
    assert a.input_names == b.input_names == ["inputs", "compressed", "seen_filtered", "bounce_filtered"]
    inputs = random_inputs(passes=2)
    expected = a.run(inputs)
    np.testing.assert_allclose(b.run(inputs), expected, rtol=1e-5, atol=1e-6 * np.abs(expected).max())
    # with walls, given or made on the filter's thread as the field's encoder asks for them
    from viewer.scene import load

    enc = encoding.encode_scene(load("cornell"), 8, 16)
    walls = encoding_walls(enc)
    expected = a.run(enc.inputs, walls)
    for given in (walls, lambda: walls):
        np.testing.assert_allclose(b.run(enc.inputs, given), expected, rtol=1e-5, atol=1e-6 * np.abs(expected).max())
    assert not np.allclose(b.run(enc.inputs), expected, rtol=1e-5, atol=1e-6 * np.abs(expected).max())
    card = json.loads(cut.with_suffix(".json").read_text())
    del card["tail"]
    cut.with_suffix(".json").write_text(json.dumps(card))
    with pytest.raises(neural.ModelError, match="no tail gains"):
        neural.NeuralField(cut)


def test_a_cut_graphs_weights_read_back_with_its_gains(tmp_path):
    """A fine-tune can start from a cut export alone: the gains come back from its card."""
    model = random_model()
    _, cut = graphs(tmp_path, model)
    export.write_card(cut, model, 8, training={"note": "random weights, for tests"}, metrics={})
    back = export.read_back(cut)
    gains = (float(back.bounce_gain.detach()), float(back.seen_gain.detach()))
    assert gains == pytest.approx((0.3, 0.8))
    assert export.split_tail(cut) is None   # nothing left to cut: the file stays as it is


def test_an_exported_network_is_cut_in_place_by_the_command(tmp_path, capsys):
    """`python -m viewer.training.export FILE --split-tail`: the shipped network was cut this way. Its card
    gets the gains and the new sha256, the field's output stays; a second cut is refused (exit 2)."""
    model = random_model()
    whole = tmp_path / "net.onnx"
    export.export_onnx(model, whole, 8, tail=False)
    export.write_card(whole, model, 8, training={"note": "random weights, for tests"}, metrics={})
    card = json.loads(whole.with_suffix(".json").read_text())
    card["inputs"]["voxels"] = 16
    whole.with_suffix(".json").write_text(json.dumps(card))
    inputs = random_inputs(passes=1)
    expected = neural.NeuralField(whole).run(inputs)
    assert export.main([str(whole), "--split-tail"]) == 0
    cut = json.loads(whole.with_suffix(".json").read_text())
    assert cut["tail"] == pytest.approx({"bounce_gain": 0.3, "seen_gain": 0.8}) and cut["outputs"]["name"] == HEAD
    assert cut["sha256"] == neural.file_sha256(whole) != card["sha256"]
    field = neural.NeuralField(whole)
    np.testing.assert_allclose(field.run(inputs), expected, rtol=1e-5, atol=1e-6 * np.abs(expected).max())
    with pytest.raises(SystemExit) as exit_:
        export.main([str(whole), "--split-tail"])
    assert exit_.value.code == 2 and "no head and gains to cut" in capsys.readouterr().err
