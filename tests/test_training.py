"""Training ProbeNet end to end on a tiny dataset: the loss falls, a run resumes where it stopped, and
the export loads in the viewer's neural source."""

import io
import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="the train extra (torch) is needed")

from viewer import neural  # noqa: E402
from viewer.training import dataset, generate, shards, truth  # noqa: E402
from viewer.training.models import ProbeNet, ProbeNetConfig  # noqa: E402
from viewer.training.samples import load_split  # noqa: E402
from viewer.training.train import History, TrainSettings, train  # noqa: E402

pytestmark = pytest.mark.skipif(not truth.mitsuba_available(), reason="the tiny dataset's truth is Mitsuba")


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """Five procedural rooms (four to train, one to validate; the first dataset's ranges), 8^3 probes,
    few directions, made on Ray by the dataset command's `run`."""
    pytest.importorskip("ray", reason="the dataset command runs on Ray")
    root = tmp_path_factory.mktemp("tiny-dataset")
    settings = shards.Settings(seed=3, ranges="v1", truth="mitsuba", directions=32, probes=(8,),
                               counts={"paper": 7, "val": 1, "train": 4})
    generate.run(root, settings, ("val", "train"), workers=2, stream=io.StringIO())
    return root


def test_loss_falls_and_the_run_resumes(tiny, tmp_path):
    train_set, val_set = load_split(tiny, "train", 8, quiet=True), load_split(tiny, "val", 8, quiet=True)
    assert train_set.inputs.shape[1:3] == (3, 21) and train_set.targets.shape[2] == 18
    run = tmp_path / "run"
    model = ProbeNet(ProbeNetConfig(width=4, hidden=8, levels=2))
    first = train(model, train_set, val_set, TrainSettings(epochs=30, batch=1, learning_rate=1e-2), run=run,
                  quiet=True)
    # the untrained network answers with the direct light (zero-initialized head): training must improve
    # on that; how much depends on the four random rooms (the shipped model's accuracy is tested apart)
    assert np.mean(first.train[-5:]) < 0.95 * np.mean(first.train[:3])
    assert (run / "checkpoint.pt").exists() and (run / "loss.png").exists()
    again = ProbeNet(ProbeNetConfig(width=4, hidden=8, levels=2))
    resumed = train(again, train_set, val_set, TrainSettings(epochs=32, batch=1, learning_rate=1e-2), run=run,
                    quiet=True)
    assert resumed.epochs == list(range(32))  # epochs 0-29 from the checkpoint, 30-31 trained now
    assert resumed.train[:30] == first.train
    saved = History(**json.loads((run / "history.json").read_text()))
    assert saved.epochs == resumed.epochs


def test_export_runs_in_the_neural_source(tiny, tmp_path):
    from viewer.training import export
    from viewer.training.samples import ENCODING_VOXELS

    train_set, val_set = load_split(tiny, "train", 8, quiet=True), load_split(tiny, "val", 8, quiet=True)
    run = tmp_path / "run"
    train(ProbeNet(ProbeNetConfig(width=4, hidden=8, levels=2)), train_set, val_set,
          TrainSettings(epochs=2, batch=2), run=run, quiet=True)
    inputs = train_set.inputs[0].astype(np.float32)
    card = export.export(run, tmp_path / "m.onnx", 8, inputs, {"note": "test"}, {})
    assert card["metrics"]["onnx_max_difference"] < 1e-4 and card["inputs"]["voxels"] == ENCODING_VOXELS
    example = dataset.load_example(dataset.room_refs(tiny, "val")[0])
    grid = neural.NeuralField(tmp_path / "m.onnx").solve(example.scene)
    assert grid.coefficients.shape == (8, 8, 8, 9, 3) and np.all(np.isfinite(grid.coefficients))
