"""The paper's network families (Table 1): their input is built the same way in training (torch) and in
the benchmark (numpy + onnxruntime), and an exported family answers in the benchmark as in torch."""

import numpy as np
import pytest

from viewer.neural.paper_inputs import PAPER_PROBES, adaptive_pool

torch = pytest.importorskip("torch", reason="the train extra (torch) is needed")

from viewer.scene import load  # noqa: E402
from viewer.bench.paper_families import PaperFamily, paper_family_methods  # noqa: E402
from viewer.training import paper_models as pm  # noqa: E402
from viewer.training import table1  # noqa: E402


@pytest.mark.parametrize("rows", [3, 128, 1000])
def test_numpy_pooling_is_torchs_adaptive_average_pooling(rows):
    voxel_rows = np.random.default_rng(rows).normal(size=(rows, pm.VOXEL_FEATURES)).astype(np.float32)
    theirs = torch.nn.AdaptiveAvgPool1d(128)(torch.from_numpy(voxel_rows.T)[None])[0].numpy()
    np.testing.assert_allclose(adaptive_pool(voxel_rows, 128), theirs, atol=1e-6)


class Stats:
    """A standardization as table1.Standardized holds it, with a non-trivial input range."""

    def __init__(self, rng):
        self.lo, self.hi = np.full(10, -0.2), rng.uniform(0.5, 20, 10)
        self.mean, self.std = rng.normal(size=PAPER_PROBES ** 3 * 27), rng.uniform(0.5, 2, PAPER_PROBES ** 3 * 27)


@pytest.mark.parametrize("family", ["mlp", "rnn"])
def test_an_exported_family_answers_in_the_benchmark_as_in_torch(family, tmp_path):
    torch.manual_seed(0)
    model = pm.PaperNet(table1.paper_config(family)).eval()
    stats = Stats(np.random.default_rng(1))
    path = table1.model_path(tmp_path, family, 1e-5)
    table1.export_family(model, stats, path)

    scene = load("cornell")
    field = PaperFamily(path)
    x = field.inputs(scene)
    assert x.shape == (1, pm.VOXEL_FEATURES, model.config.pooled) and np.abs(x).max() <= 1
    grid = field.solve(scene)
    with torch.no_grad():
        theirs = model.head(torch.from_numpy(x)).numpy()[0] * stats.std + stats.mean
    np.testing.assert_allclose(grid.coefficients.reshape(-1), theirs, rtol=1e-4, atol=1e-4)
    assert grid.coefficients.shape == (PAPER_PROBES,) * 3 + (9, 3)
    np.testing.assert_allclose(grid.lo, scene.bounds[0])

    (method,) = paper_family_methods(folder=tmp_path)
    assert method.family == "paper-family" and method.setting == f"{'RNN' if family == 'rnn' else 'MLP'} lambda=1e-05"
    assert method.model_bytes == path.stat().st_size
    assert paper_family_methods(quick=True, folder=tmp_path) == []
