"""The model card (viewer/neural/card.py): what it tells the neural source (the seen rays to cast, whether
the direct input carries the probes' shadows, the filter's kernels), what a card written before it said
so gets, and the refusal of a bad model or card in one line."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from viewer.neural import encoding
from viewer.neural import field as neural
from viewer.scene import load

pytest.importorskip("torch", reason="the train extra (torch) is needed to build models in tests")

from tiny_network import export_tiny  # noqa: E402 - needs torch

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A random model exported with a card, as the training pipeline writes it."""
    return export_tiny(tmp_path_factory.mktemp("models"))


@pytest.mark.parametrize("damage", ["garbage", "truncated", "no-card", "bad-card", "sha", "version", "rays"])
def test_bad_model_is_refused_with_a_clear_message(exported, tmp_path, damage):
    _, path = exported
    target = tmp_path / "model.onnx"
    shutil.copy(path, target)
    shutil.copy(path.with_suffix(".json"), target.with_suffix(".json"))
    card = json.loads(target.with_suffix(".json").read_text())
    if damage == "garbage":
        target.write_bytes(b"\x00not an onnx file" * 64)
        card["sha256"] = neural.file_sha256(target)
    elif damage == "truncated":
        target.write_bytes(path.read_bytes()[:2000])
        card["sha256"] = neural.file_sha256(target)
    elif damage == "no-card":
        target.with_suffix(".json").unlink()
    elif damage == "bad-card":
        card = {"name": "x"}
    elif damage == "sha":
        card["sha256"] = "0" * 64
    elif damage == "version":
        card["inputs"]["encoding_version"] = encoding.VERSION + 1
    elif damage == "rays":
        card["inputs"]["seen_rays"] = 0
    if damage != "no-card":
        target.with_suffix(".json").write_text(json.dumps(card))
    with pytest.raises(neural.ModelError) as info:
        neural.NeuralField(target)
    message = str(info.value)
    assert "\n" not in message and "model" in message.lower() or target.name in message


def test_the_runtime_casts_the_seen_rays_the_card_names(exported, tmp_path):
    """A network learns on features of a number of seen rays a probe; the card names it (the export
    writes the encoding's), and the source casts that many, in a new scene and after a move. A card
    written before cards named it gets the encoding's count. The same network fed other rays gives
    other probes."""
    _, path = exported
    assert json.loads(path.with_suffix(".json").read_text())["inputs"]["seen_rays"] == encoding.SEEN_RAYS
    shipped = neural.ModelCard.read(ROOT / "models" / "probenet.onnx")
    assert shipped.seen_rays == encoding.SEEN_RAYS
    target = tmp_path / "model.onnx"
    shutil.copy(path, target)
    card = json.loads(path.with_suffix(".json").read_text())
    card["inputs"]["seen_rays"] = 8
    target.with_suffix(".json").write_text(json.dumps(card))
    scene = load("cornell")
    field = neural.NeuralField(target)
    eight = field.solve(scene)
    assert field.encoder(*scene.bounds, field.resolution).seen.rays == 8
    matrix = np.eye(4)
    matrix[0, 3] = 0.05
    moved = scene.transformed_group("small-box", matrix)   # kept rays and rays cast again: 8 a probe
    gi = neural.NeuralGI(field)
    gi.update(scene)
    gi.update(moved)
    assert field.encoder(*moved.bounds, field.resolution).seen.rays == 8
    del card["inputs"]["seen_rays"]
    target.with_suffix(".json").write_text(json.dumps(card))
    older = neural.NeuralField(target)
    assert older.card.seen_rays == encoding.SEEN_RAYS
    default = older.solve(scene)
    assert older.encoder(*scene.bounds, older.resolution).seen.rays == encoding.SEEN_RAYS
    assert not np.allclose(eight.coefficients, default.coefficients)


def test_the_probes_direct_light_is_shadowed_as_the_card_says(exported, tmp_path):
    """A card written before cards said whether the network's direct input carries the probes' shadows
    had them; the runtime encodes as the card says. Without them, the all-light probes take the
    shadowed direct light computed apart, so both networks' all-light probes minus their reflected
    light are the same shadowed direct light; the reflected light differs (the network read other
    inputs), and a drag keeps every unshadowed basis."""
    _, path = exported
    assert neural.ModelCard.read(ROOT / "models" / "probenet.onnx").direct_shadows is encoding.DIRECT_SHADOWS
    target = tmp_path / "model.onnx"
    shutil.copy(path, target)
    card = json.loads(path.with_suffix(".json").read_text())
    fields, direct = {}, {}
    scene = load("cornell")
    for shadows in (True, False):
        card["inputs"]["direct_shadows"] = shadows
        if shadows:
            del card["inputs"]["direct_shadows"]
        target.with_suffix(".json").write_text(json.dumps(card))
        field = fields[shadows] = neural.NeuralField(target)
        assert field.card.direct_shadows is shadows
        every, reflected = field.solve(scene), field.solve(scene, include_emitted=False)
        assert field.encoder(*scene.bounds, field.resolution).direct_shadows is shadows
        direct[shadows] = (every.coefficients - reflected.coefficients, reflected.coefficients)
    np.testing.assert_allclose(direct[False][0], direct[True][0], rtol=1e-4, atol=1e-5 * np.abs(direct[True][0]).max())
    assert not np.allclose(direct[False][1], direct[True][1])
    gi = neural.NeuralGI(fields[False])
    gi.update(scene)
    bases = [e.basis for e in fields[False].encoder(*scene.bounds, 8).emitters]
    matrix = np.eye(4)
    matrix[0, 3] = 0.05
    gi.update(scene.transformed_group("large-box", matrix))
    kept = [e.basis for e in fields[False].encoder(*scene.bounds, 8).emitters]
    assert len(kept) == len(bases) and all(a is b for a, b in zip(kept, bases))


def test_sample_with_a_missing_model_exits_2(tmp_path):
    points = tmp_path / "p.npy"
    np.save(points, np.zeros((4, 3), np.float32))
    result = subprocess.run([sys.executable, "-m", "viewer", "sample", "cornell", "--points", str(points),
                             "--method", "neural", "--model", str(tmp_path / "none.onnx"),
                             "--out", str(tmp_path / "o.npy")], capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1 and "no trained model" in result.stderr


def test_a_network_that_takes_its_filter_needs_the_kernels_on_its_card(exported, tmp_path):
    model, path = exported
    card = json.loads(path.with_suffix(".json").read_text())
    del card["inputs"]["filtered"]["kernels"]
    copy = tmp_path / "no-kernels.onnx"
    copy.write_bytes(path.read_bytes())
    copy.with_suffix(".json").write_text(json.dumps({**card, "file": copy.name}))
    with pytest.raises(neural.ModelError, match="kernels"):
        neural.NeuralField(copy)
