"""Train ProbeNet on the dataset: one command, a progress line per epoch, checkpoints and a loss curve.

    python -m viewer.training.train --data data/gi-v1 --out runs/probenet [--width 8 --hidden 16]
                                    [--epochs 60] [--probes 16]

Loss: mean squared error of the SH in units of the encoding's scale (every probe, the filled targets)
plus a small binary cross-entropy for the validity logit. Augmentation: mirror images in x and in z
(a mirrored room is a room; the odd SH coefficients change sign). The run directory keeps
`checkpoint.pt` (resumed when the command is run again), `history.json` and `loss.png`.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch.nn import functional as F

from viewer import encoding
from viewer.training.models import REFLECTED, TOTAL, VALIDITY, ProbeNet, ProbeNetConfig, parameter_count
from viewer.training.samples import Samples, load_split, training_split

ODD_IN = {0: [3, 4, 7], 2: [2, 5, 7]}
"""SH coefficients that change sign when the x axis (or the z axis) is mirrored (DESIGN.md order:
00, 1-1 (y), 10 (z), 11 (x), 2-2 (xy), 2-1 (yz), 20, 21 (xz), 22 (x^2 - y^2))."""
NORMAL_CHANNEL = {0: 1, 2: 3}
COORD_CHANNEL = {0: 15, 2: 17}
VALIDITY_WEIGHT = 0.05


@dataclass
class TrainSettings:
    epochs: int = 60
    """Passes over the training split."""
    batch: int = 2
    """Scenes per step (x3 colour channels). Small: with a few hundred scenes, more steps beat bigger
    batches (batch 2 reached in one epoch the validation error batch 8 reached in six)."""
    learning_rate: float = 3e-3
    """Adam's step size at the start; cosine decay to 1/30 of it."""
    weight_decay: float = 0.0
    """lambda of the L2 penalty on the weights (the paper's regularizer)."""
    augment: bool = True
    """Random mirror images in x and z."""
    seed: int = 0
    threads: int = 2


@dataclass
class History:
    epochs: list[int] = field(default_factory=list)
    train: list[float] = field(default_factory=list)
    val: list[float] = field(default_factory=list)
    val_relative_rmse: list[float] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)


def mirror(inputs: torch.Tensor, targets: torch.Tensor, valid: torch.Tensor, axis: int):
    """The mirror image in world axis `axis` (0 = x, 2 = z) of a batch (B, C, X, Y, Z)."""
    dim = 2 + axis
    inputs, targets, valid = inputs.flip(dim), targets.flip(dim), valid.flip(dim - 1)
    sign_in = torch.ones(encoding.CHANNELS)
    sign_in[NORMAL_CHANNEL[axis]] = -1
    sign_in[COORD_CHANNEL[axis]] = -1
    for k in ODD_IN[axis]:
        sign_in[encoding.DIRECT.start + k] = -1
    sign_out = torch.ones(18)
    sign_out[ODD_IN[axis]] = -1
    sign_out[[9 + k for k in ODD_IN[axis]]] = -1
    return inputs * sign_in[:, None, None, None], targets * sign_out[:, None, None, None], valid


def batches(samples: Samples, indices: np.ndarray, size: int):
    for start in range(0, len(indices), size):
        pick = np.sort(indices[start:start + size])
        m = samples.inputs.shape[-1]
        x = torch.from_numpy(samples.inputs[pick].astype(np.float32)).reshape(-1, encoding.CHANNELS, m, m, m)
        y = torch.from_numpy(samples.targets[pick]).reshape(-1, 18, m, m, m)
        v = torch.from_numpy(np.repeat(samples.valid[pick], 3, axis=0).astype(np.float32))
        yield pick, x, y, v


def loss_terms(model, x, y, v):
    """(MSE of all 18 SH outputs, BCE of the validity logit, the outputs)."""
    out = model(x)
    sh_loss = F.mse_loss(out[:, :18], y)
    valid_loss = F.binary_cross_entropy_with_logits(out[:, VALIDITY], v)
    return sh_loss, valid_loss, out


def evaluate(model, samples: Samples, batch: int = 8, part: slice = TOTAL) -> tuple[float, float]:
    """(MSE in scaled units, relative RMSE of every probe's SH in radiance units) over a split, for one
    part of the output (all the light by default, or REFLECTED)."""
    model.eval()
    total, count, err, ref = 0.0, 0, 0.0, 0.0
    with torch.no_grad():
        for pick, x, y, v in batches(samples, np.arange(len(samples)), batch):
            sh_loss, _, out = loss_terms(model, x, y, v)
            total += float(sh_loss) * len(pick)
            count += len(pick)
            scale = torch.from_numpy(samples.scale[pick]).reshape(-1, 1, 1, 1, 1)
            err += float((((out[:, part] - y[:, part]) * scale) ** 2).sum())
            ref += float(((y[:, part] * scale) ** 2).sum())
    model.train()
    return total / max(count, 1), math.sqrt(err / max(ref, 1e-30))


def train(model: ProbeNet, train_set: Samples, val_set: Samples, settings: TrainSettings,
          run: Path | None = None, quiet: bool = False) -> History:
    torch.manual_seed(settings.seed)
    torch.set_num_threads(settings.threads)
    rng = np.random.default_rng(settings.seed)
    optimizer = torch.optim.Adam(model.parameters(), lr=settings.learning_rate)
    steps_per_epoch = math.ceil(len(train_set) / settings.batch)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(
        optimizer, settings.epochs * steps_per_epoch, eta_min=settings.learning_rate / 30)
    history, first = History(), 0
    checkpoint = run / "checkpoint.pt" if run else None
    if checkpoint and checkpoint.exists():
        state = torch.load(checkpoint, weights_only=False)
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        schedule.load_state_dict(state["schedule"])
        history = History(**state["history"])
        first = history.epochs[-1] + 1 if history.epochs else 0
        rng = np.random.default_rng([settings.seed, first])
    for epoch in range(first, settings.epochs):
        start = time.perf_counter()
        running, seen = 0.0, 0
        for pick, x, y, v in batches(train_set, rng.permutation(len(train_set)), settings.batch):
            if settings.augment:
                for axis in (0, 2):
                    if rng.random() < 0.5:
                        x, y, v = mirror(x, y, v, axis)
            sh_loss, valid_loss, _ = loss_terms(model, x, y, v)
            loss = sh_loss + VALIDITY_WEIGHT * valid_loss
            if settings.weight_decay > 0:
                loss = loss + settings.weight_decay * sum((p ** 2).sum() for p in model.parameters() if p.dim() > 1)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            schedule.step()
            running += float(sh_loss.detach()) * len(pick)
            seen += len(pick)
        val_mse, val_rel = evaluate(model, val_set)
        history.epochs.append(epoch)
        history.train.append(running / seen)
        history.val.append(val_mse)
        history.val_relative_rmse.append(val_rel)
        history.seconds.append(time.perf_counter() - start)
        if not quiet:
            print(f"epoch {epoch + 1}/{settings.epochs}  train {running / seen:.5f}  val {val_mse:.5f}  "
                  f"val rel. RMSE {100 * val_rel:.2f}%  ({history.seconds[-1]:.1f} s)", file=sys.stderr)
        if run:
            run.mkdir(parents=True, exist_ok=True)
            torch.save({"model": model.state_dict(), "optimizer": optimizer.state_dict(),
                        "schedule": schedule.state_dict(), "history": history.__dict__,
                        "config": model.config.to_dict()}, checkpoint)
            (run / "history.json").write_text(json.dumps(history.__dict__, indent=1))
    if run:
        plot_history(history, run / "loss.png", title=run.name)
    return history


def plot_history(history: History, path: Path, title: str = "") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.6), dpi=110)
    epochs = np.array(history.epochs) + 1
    ax.semilogy(epochs, history.train, label="train MSE (scaled SH)")
    ax.semilogy(epochs, history.val, label="validation MSE")
    ax.set_xlabel("epoch")
    ax.set_ylabel("MSE")
    ax.grid(True, which="both", alpha=0.3)
    twin = ax.twinx()
    twin.plot(epochs, 100 * np.array(history.val_relative_rmse), color="tab:red", ls="--",
              label="validation rel. RMSE (%)")
    twin.set_ylabel("rel. RMSE (%)")
    lines = ax.get_legend_handles_labels()
    more = twin.get_legend_handles_labels()
    ax.legend(lines[0] + more[0], lines[1] + more[1], fontsize=8)
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m viewer.training.train", description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path("data/gi-v1"))
    parser.add_argument("--out", type=Path, required=True, help="run directory (resumed if it exists)")
    parser.add_argument("--probes", type=int, default=16)
    parser.add_argument("--width", type=int, default=ProbeNetConfig.width)
    parser.add_argument("--hidden", type=int, default=ProbeNetConfig.hidden)
    parser.add_argument("--head-layers", type=int, default=ProbeNetConfig.head_layers)
    parser.add_argument("--levels", type=int, default=ProbeNetConfig.levels)
    parser.add_argument("--epochs", type=int, default=TrainSettings.epochs)
    parser.add_argument("--batch", type=int, default=TrainSettings.batch, help="scenes per step")
    parser.add_argument("--lr", type=float, default=TrainSettings.learning_rate)
    parser.add_argument("--weight-decay", type=float, default=0.0)
    parser.add_argument("--limit", type=int, default=0, help="use only the first N training scenes")
    args = parser.parse_args(argv)
    train_set = training_split(args.data, args.probes)
    val_set = load_split(args.data, "val", args.probes)
    if args.limit:
        train_set = subset(train_set, np.arange(min(args.limit, len(train_set))))
    config = ProbeNetConfig(width=args.width, hidden=args.hidden, head_layers=args.head_layers, levels=args.levels)
    model = ProbeNet(config)
    print(f"ProbeNet {config}: {parameter_count(model)} parameters, {len(train_set)} training scenes",
          file=sys.stderr)
    settings = TrainSettings(epochs=args.epochs, batch=args.batch, learning_rate=args.lr,
                             weight_decay=args.weight_decay)
    train(model, train_set, val_set, settings, run=args.out)
    return 0


def subset(samples: Samples, indices: np.ndarray) -> Samples:
    return Samples(samples.inputs[indices], samples.targets[indices], samples.valid[indices],
                   samples.scale[indices], [samples.names[i] for i in indices])


if __name__ == "__main__":
    raise SystemExit(main())
