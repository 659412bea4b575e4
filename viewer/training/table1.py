"""The paper's Table 1, reproduced: the five families with and without L2 regularization on the same
splits, train / validation / test MSE on standardized coefficients, and relative RMSE in radiance units.

    python -m viewer.training.table1 --data data/gi-v2 [--epochs 200] [--out docs/TABLE1.md] [--models runs/table1]

Splits: train = the procedural `train` split plus the paper's five training layouts; validation = the
procedural `val` split (new layouts from the same distribution); test = `paper-test` (the held-out scene
of the paper: a new sphere and a pink back wall). Targets: the dataset's 8^3 ground-truth probes (read
out of a 24^3 dataset: every third probe is an 8^3 one, `dataset.coarser_lattices`).
The production network (ProbeNet, 8^3 lattice) is trained on the same data and scored the same way,
as a last row.

Each trained family is exported to `--models` as `{family}-l{lambda}.onnx` (the network after the
pooling layer, one scene a call) with `{...}.npz` beside it (the standardization: input range, output
mean and std, pooled length), so that the benchmark can run it through onnxruntime
(`viewer.bench.paper_families`).
"""

from __future__ import annotations

import warnings
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch
from torch.nn import functional as F

from viewer.evaluation.report import replace_block
from viewer.training import paper_models as pm
from viewer.neural.paper_inputs import PAPER_VOXELS, adaptive_pool, voxel_list
from viewer.training.samples import Samples, encoded_split, load_split, room_of, training_split

ROOT = Path(__file__).resolve().parents[2]
LAMBDA = 1e-5
"""The regularized runs' lambda (sum of squared weights)."""
PAPER_REPORTED = {"mlp": "0.003-0.007", "cnn": "0.6-0.78"}


def paper_encode(path: str, resolution: int) -> dict[str, np.ndarray]:
    from viewer.training.dataset import load_example
    from viewer.rays.voxels import voxelize

    example = load_example(path)
    rows = voxel_list(voxelize(example.scene, PAPER_VOXELS))
    pooled = adaptive_pool(rows, pm.PaperConfig.pooled)
    return {"pooled": pooled, "rows_min": rows.min(0), "rows_max": rows.max(0),
            "targets": example.targets[resolution].reshape(-1), "names": np.array(room_of(path))}


class Split:
    """One split for the paper families: pooled voxel lists (raw units) and flattened 8^3 targets."""

    def __init__(self, arrays: dict, keep: np.ndarray | None = None):
        keep = np.arange(len(arrays["names"])) if keep is None else keep
        self.pooled = arrays["pooled"][keep]
        self.rows_min, self.rows_max = arrays["rows_min"][keep], arrays["rows_max"][keep]
        self.targets = arrays["targets"][keep].astype(np.float64)
        self.names = [str(n) for n in arrays["names"][keep]]

    @staticmethod
    def join(a: "Split", b: "Split") -> "Split":
        out = Split.__new__(Split)
        for name in ("pooled", "rows_min", "rows_max", "targets"):
            setattr(out, name, np.concatenate([getattr(a, name), getattr(b, name)]))
        out.names = a.names + b.names
        return out


class Standardized:
    def __init__(self, train: Split):
        self.lo, self.hi = train.rows_min.min(0), train.rows_max.max(0)
        self.mean, self.std = train.targets.mean(0), train.targets.std(0) + 1e-6

    def inputs(self, split: Split) -> torch.Tensor:
        span = np.where(self.hi > self.lo, self.hi - self.lo, 1.0)
        x = (split.pooled - self.lo[None, :, None]) / span[None, :, None] * 2 - 1  # commutes with the pooling
        return torch.from_numpy(np.clip(x, -1, 1).astype(np.float32))

    def targets(self, split: Split) -> torch.Tensor:
        return torch.from_numpy(((split.targets - self.mean) / self.std).astype(np.float32))


def relative_rmse(estimate: np.ndarray, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean((estimate - truth) ** 2) / np.mean(truth ** 2)))


def train_family(config: pm.PaperConfig, data: dict, std: Standardized, weight_decay: float, epochs: int,
                 seed: int = 0) -> tuple[dict, list, pm.PaperNet]:
    torch.manual_seed(seed)
    model = pm.PaperNet(config)
    x, y = std.inputs(data["train"]), std.targets(data["train"])
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, epochs, eta_min=3e-5)
    rng = np.random.default_rng(seed)
    curve = []
    for epoch in range(epochs):
        model.train()
        total = 0.0
        order = rng.permutation(len(x))
        for start in range(0, len(x), 32):
            pick = torch.from_numpy(order[start:start + 32])
            mse = F.mse_loss(model.head(x[pick]), y[pick])
            loss = mse
            if weight_decay > 0:
                loss = loss + weight_decay * sum((p ** 2).sum() for n, p in model.named_parameters() if "weight" in n)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            total += float(mse.detach()) * len(pick)
        schedule.step()
        if epochs <= 20 or epoch % 10 == 9 or epoch == epochs - 1:   # a short run: every epoch
            curve.append((epoch + 1, total / len(x), score(model, data["val"], std)[0]))
    scores = {name: score(model, split, std) for name, split in data.items()}
    return scores, curve, model


def model_path(folder: Path, family: str, weight_decay: float) -> Path:
    return folder / f"{family}-l{weight_decay:g}.onnx"


def export_family(model: pm.PaperNet, std: Standardized, path: Path) -> None:
    """The network after its pooling layer as ONNX (input `pooled` (1, 10, L) standardized, output
    `probes` (1, 8^3 x 27) standardized), and the standardization beside it as .npz."""
    model.eval()
    example = torch.zeros(1, pm.VOXEL_FEATURES, model.config.pooled)
    path.parent.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(_Head(model), (example,), str(path), input_names=["pooled"], output_names=["probes"],
                          dynamo=False)
    np.savez(path.with_suffix(".npz"), lo=std.lo, hi=std.hi, mean=std.mean, std=std.std,
             pooled=model.config.pooled, family=model.config.family)


class _Head(torch.nn.Module):
    """`PaperNet.head` as a module's forward, for the exporter."""

    def __init__(self, model: pm.PaperNet):
        super().__init__()
        self.model = model

    def forward(self, pooled: torch.Tensor) -> torch.Tensor:
        return self.model.head(pooled)


def score(model, split: Split, std: Standardized) -> tuple[float, float]:
    """(MSE on standardized coefficients, relative RMSE in radiance units)."""
    model.eval()
    with torch.no_grad():
        out = model.head(std.inputs(split)).numpy()
    mse = float(np.mean((out - std.targets(split).numpy()) ** 2))
    return mse, relative_rmse(out * std.std + std.mean, split.targets)


def probenet_row(root: Path, data: dict, std: Standardized, epochs: int) -> tuple[dict, list, int]:
    """ProbeNet on the 8^3 lattice, scored in the paper's standardized units too: (scores, loss curve,
    parameters)."""
    from viewer.training.models import ProbeNet, ProbeNetConfig
    from viewer.training.train import TrainSettings, train

    m = pm.PAPER_PROBES
    train_set = training_split(root, m)
    val_set = load_split(root, "val", m)
    paper = load_split(root, "paper", m)
    test_set = paper.subset([paper.names.index("paper-test")])
    model = ProbeNet(ProbeNetConfig(width=8, hidden=16, levels=3))
    history = train(model, train_set, val_set, TrainSettings(epochs=epochs), quiet=True)
    scores = {}
    for name, samples, split in (("train", train_set, data["train"]), ("val", val_set, data["val"]),
                                 ("test", test_set, data["test"])):
        predicted = predict_physical(model, samples)  # (S, M, M, M, 9, 3)
        flat = predicted.reshape(len(samples), -1)
        order = [samples.names.index(n) for n in split.names]
        flat = flat[order]
        standardized = (flat - std.mean) / std.std
        mse = float(np.mean((standardized - (split.targets - std.mean) / std.std) ** 2))
        scores[name] = (mse, relative_rmse(flat, split.targets))
    curve = list(zip(np.array(history.epochs) + 1, history.train, history.val))
    return scores, curve, sum(p.numel() for p in model.parameters())


def predict_physical(model, samples: Samples) -> np.ndarray:
    from viewer.training.train import batches

    model.eval()
    outs = []
    with torch.no_grad():
        for b in batches(samples, np.arange(len(samples)), 8):
            outs.append(model(b.x)[:, :9].numpy().reshape(len(b.pick), 3, 9, *b.x.shape[-3:]))  # all the light
    normalized = np.concatenate(outs)
    return samples.physical(normalized)


def load_data(root: Path) -> dict[str, Split]:
    m = pm.PAPER_PROBES
    paper = encoded_split(root, "paper", "paper-list", paper_encode, m)
    names = [str(n) for n in paper["names"]]
    train_names = np.array([i for i, n in enumerate(names) if n.startswith("paper-train")])
    test = np.array([names.index("paper-test")])
    return {"train": Split.join(Split(encoded_split(root, "train", "paper-list", paper_encode, m)),
                                Split(paper, train_names)),
            "val": Split(encoded_split(root, "val", "paper-list", paper_encode, m)),
            "test": Split(paper, test)}


def main(argv=None) -> int:
    from viewer.cli_parsing import add_data, add_out, tool_parser

    parser = tool_parser(__doc__, prog="python -m viewer.training.table1")
    add_data(parser)
    parser.add_argument("--epochs", type=int, default=200)
    parser.add_argument("--families", default=",".join(pm.FAMILIES + ("probenet",)))
    add_out(parser, ROOT / "docs" / "TABLE1.md")
    parser.add_argument("--results", type=Path, default=ROOT / "docs" / "data" / "table1.json")
    parser.add_argument("--models", type=Path, default=ROOT / "runs" / "table1",
                        help="where the trained families are exported for the benchmark")
    args = parser.parse_args(argv)
    torch.set_num_threads(2)
    data = load_data(args.data)
    std = Standardized(data["train"])
    results = json.loads(args.results.read_text()) if args.results.exists() else {}
    for family in args.families.split(","):
        for weight_decay in ((0.0,) if family == "probenet" else (0.0, LAMBDA)):
            key = f"{family}|{weight_decay:g}"
            exported = family == "probenet" or model_path(args.models, family, weight_decay).is_file()
            done = results.get(key, {})
            if done.get("epochs") == args.epochs and done.get("data") == str(args.data) and exported:
                continue
            start = time.perf_counter()
            if family == "probenet":
                scores, curve, parameters = probenet_row(args.data, data, std, max(args.epochs // 4, 1))
            else:
                scores, curve, model = train_family(paper_config(family), data, std, weight_decay, args.epochs)
                export_family(model, std, model_path(args.models, family, weight_decay))
                parameters = sum(p.numel() for p in model.parameters())
            results[key] = {"family": family, "lambda": weight_decay, "epochs": args.epochs, "scores": scores,
                            "trained_epochs": max(args.epochs // 4, 1) if family == "probenet" else args.epochs,
                            "curve": [list(map(float, c)) for c in curve], "seconds": time.perf_counter() - start,
                            "parameters": parameters, "data": str(args.data),
                            "training_rooms": len(data["train"].names)}
            print(f"{key}: train {scores['train'][0]:.4f} val {scores['val'][0]:.4f} test {scores['test'][0]:.4f}"
                  f"  rel. RMSE test {100 * scores['test'][1]:.1f}%  ({results[key]['seconds']:.0f} s)", file=sys.stderr)
            args.results.parent.mkdir(parents=True, exist_ok=True)
            args.results.write_text(json.dumps(results, indent=1))
    write_report(results, args)
    return 0


def paper_config(family: str) -> pm.PaperConfig:
    """The RNN reads a shorter pooled list (32 instead of 128): a 128-step recurrence trains ~4x slower
    on this CPU, and the adjustable pooling layer exists to set that length."""
    return pm.PaperConfig(family=family, pooled=32 if family == "rnn" else pm.PaperConfig.pooled)


LABELS = {"mlp": "MLP", "resnet10": "ResNet-10", "rnn": "RNN", "cnn": "CNN", "cnn-mlp": "CNN-MLP",
          "probenet": "ProbeNet (ours, 8^3)"}
MARKER = "<!-- table1 -->"


def write_report(results: dict, args) -> None:
    """The table (and the loss-curve chart) into docs/TABLE1.md between the markers."""
    rows = ["| network | lambda | parameters | epochs | train MSE | val MSE | test MSE (paper-test) | val rel. RMSE | "
            "test rel. RMSE | paper's test MSE | train time |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for key, r in sorted(results.items(), key=lambda kv: (list(LABELS).index(kv[1]["family"]), kv[1]["lambda"])):
        s = r["scores"]
        rows.append(f"| {LABELS[r['family']]} | {r['lambda']:g} | {r['parameters']} | {r.get('trained_epochs', r['epochs'])} | "
                    f"{s['train'][0]:.3f} | "
                    f"{s['val'][0]:.3f} | {s['test'][0]:.3f} | {100 * s['val'][1]:.1f}% | {100 * s['test'][1]:.1f}% | "
                    f"{PAPER_REPORTED.get(r['family'], '')} | {r['seconds']:.0f} s |")
    plot_curves(results, ROOT / "docs" / "images" / "table1_curves.png")

    rooms = sorted({r.get("training_rooms") for r in results.values() if r.get("training_rooms")})
    trained = f"Every network trained on the same {' / '.join(f'{n:,}' for n in rooms)} rooms. " if rooms else ""
    table = "\n".join(rows) + f"\n\n![loss curves](images/table1_curves.png)\n\n{trained}Command: " \
        f"`python -m viewer.training.table1 --data {args.data} --epochs {args.epochs}`\n"
    replace_block(args.out, MARKER, table, "# Table 1 of the paper, reproduced")


def plot_curves(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), dpi=110, sharey=True)
    for ax, lam in zip(axes, (0.0, LAMBDA)):
        for r in results.values():
            if r["lambda"] != lam or not r["curve"]:
                continue
            curve = np.array(r["curve"])
            units = " (its own loss: scaled SH)" if r["family"] == "probenet" else ""
            # markers: a short run records its curve at one or two epochs only
            line, = ax.semilogy(curve[:, 0], curve[:, 1], marker="o", label=f"{LABELS[r['family']]} train{units}")
            ax.semilogy(curve[:, 0], curve[:, 2], ls="--", marker="x", color=line.get_color())
        ax.set_title(f"lambda = {lam:g} (solid: train, dashed: validation)")
        ax.set_xlabel("epoch")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("MSE, standardized coefficients")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
