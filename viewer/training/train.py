"""Train ProbeNet on the dataset: one command, a progress line per epoch, checkpoints and a loss curve.

    python -m viewer.training.train --data data/gi-v2 --out runs/probenet [--width 8 --hidden 16]
                                    [--epochs 60] [--steps 500] [--probes 24]

The rooms stream from the memory-mapped shard caches (`viewer.training.samples`): thousands of rooms at
24^3 fit in a few gigabytes of memory. Loss (`loss_terms`): the light straight from the emitters against
the truth, plus the reflected light (what the renderer shades) against Mitsuba's unbiased probes where a
room has them and the solver's elsewhere, weighted up; and a small binary cross-entropy for the
validity logit. Augmentation: mirror images in x and in z (a mirrored room is a room; the odd SH
coefficients change sign). The run directory keeps `checkpoint.pt` (resumed when the command is run
again), `history.json`, `data.json` (what it trained on) and `loss.png`.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch.nn import functional as F

from viewer.neural import encoding
from viewer.training.batches import (Batch, batches, mirror, mirror_sh,  # noqa: F401 - read from here too
                                     probe_weights, reflected_target, sh_signs, traced_direct)
from viewer.training.models import (REFLECTED, TOTAL, VALIDITY, ProbeNet, ProbeNetConfig, channel_activity,
                                    narrows, parameter_count)
from viewer.training.samples import ENCODING_VOXELS, Samples, load_split, training_split

VALIDITY_WEIGHT = 0.05
BEST = "best.pt"
"""The checkpoint of the epoch with the lowest validation loss so far (what `viewer.training.export`
ships); `checkpoint.pt` is the latest, which a resumed run continues."""


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
    reflected_weight: float = 8.0
    """Weight of the reflected light's loss against the direct light's. The direct part's squared values
    are ~20x the reflected part's (the peaks under the lamps), so at 1 the network would fit the lamps'
    neighbourhoods and leave the light the renderer shades; at 4 a relative error of the reflected part
    costs about a fifth of the same relative error of the direct part. With clipped gradients, 8 gave
    the same reflected light as 4 and all the light 0.7 points better on the validation rooms (6.6%
    against 7.3% on the public scenes: docs/TRAINING.md)."""
    solver_weight: float = 0.25
    """Weight of a room without Mitsuba's probes in the reflected loss: its physical-solver target is
    deterministic but biased (16% on v2 rooms, docs/TRAINING.md); Mitsuba's are unbiased but noisy."""
    steps: int = 0
    """Stop an epoch after this many steps (0: the whole split): a pass over thousands of rooms."""
    mitsuba: bool = True
    """Score the reflected light against Mitsuba's probes in the rooms that have them; False: against the
    solver's in every room (deterministic and biased; `solver_weight` then weighs every room)."""
    reflected_loss: str = "rmse"
    """How the reflected light's error is scored: `rmse`, each room's relative RMSE (its three colour
    passes together), averaged over the rooms: the validation's own score, where a room's bright probes
    count most and a room the network cannot fit counts once; `room`, its square (the rooms it cannot
    fit weigh most); `local`, each probe's squared error relative to all the light around it
    (`probe_weights`); `reflected`, relative to the reflected light around it. On encoding version 9
    (width 8, the same rooms and steps; the indirect light against Mitsuba at free-space points, medians
    of the public scenes / 20 validation rooms / 4 dark rooms), `local` trained the network to 16.8% /
    25.0% / 26.5% and `reflected` to 16.0% / 23.8% / 24.4%, both worse than the untrained network's
    12.0% / 21.8% / 23.1%: weighed probe by probe, the bright light by the lamps, which the score
    counts most, counts least. `rmse` trained it to 11.6% / 20.3% / 22.9%."""
    clip: float = 1.0
    """Largest gradient norm a step takes (0: no clipping). The median step's norm is about 0.5 and one
    in ten passes 1; unclipped, every run jumped at its third epoch (the same batch of the same seed) to
    50-60% off on the reflected light and took epochs to come back, and ended 1 point worse on the
    reflected light and 3 on all the light (docs/TRAINING.md)."""
    direct_input: str = "encoded"
    """What the direct-light features hold: `encoded` (the encoding's, `viewer.neural.encoding`: shadows traced
    on a coarse grid) or `traced` (the truth's own direct light: the experiment of a network whose
    direct term is exact)."""


@dataclass
class History:
    epochs: list[int] = field(default_factory=list)
    train: list[float] = field(default_factory=list)
    val: list[float] = field(default_factory=list)
    val_relative_rmse: list[float] = field(default_factory=list)
    """All the light against the truth (the solver's, for format-2 datasets)."""
    seconds: list[float] = field(default_factory=list)
    val_metrics: list[dict] = field(default_factory=list)
    """Every epoch's `evaluate` on the validation split."""


def loss_terms(model, batch: Batch, settings: "TrainSettings"):
    """(the SH loss, BCE of the validity logit, the outputs).

    The SH loss splits the light in two parts the renderer treats apart, each probe weighted by
    `probe_weights`:
    - the light straight from the emitters and the sun (all minus reflected), against the truth's (the
      physical solver traces it exactly), every room;
    - the reflected light, what the renderer shades from the probes, weighted by `reflected_weight`:
      against Mitsuba's unbiased probes where the room has them, else against the truth's (biased), the
      latter rooms weighted by `solver_weight`."""
    out = model(batch.x) if batch.links is None else model(batch.x, links=batch.links)
    if not settings.mitsuba:
        batch = batch.but(has_unbiased=torch.zeros_like(batch.has_unbiased))
    w = probe_weights(batch)
    direct = out[:, TOTAL] - out[:, REFLECTED]
    direct_loss = (w * (direct - (batch.y[:, TOTAL] - batch.y[:, REFLECTED])) ** 2).mean()
    if not encoding.DIRECT_SHADOWS:   # the direct light is computed with its shadows, not learned (`probe_direct`)
        direct_loss = direct_loss * 0.0
    room = batch.has_unbiased + (1 - batch.has_unbiased) * settings.solver_weight
    target = reflected_target(batch)
    if settings.reflected_loss in ("room", "rmse"):
        # a room's three colour passes together, as the validation scores it: per pass, a channel the
        # room barely lights (the blue of a red room) made its relative error, and the loss, explode
        err = ((out[:, REFLECTED] - target) ** 2).mean(dim=(1, 2, 3, 4)).reshape(-1, 3)
        energy = (target ** 2).mean(dim=(1, 2, 3, 4)).reshape(-1, 3)
        per_room = err.sum(dim=1) / energy.sum(dim=1).clamp_min(1e-12)
        if settings.reflected_loss == "rmse":
            per_room = (per_room + 1e-12).sqrt()
        per_row = per_room.repeat_interleave(3)
    elif settings.reflected_loss == "reflected":
        dc = target[:, 0:1].abs()
        weight = 1.0 / (dc + dc.mean(dim=(2, 3, 4), keepdim=True).clamp_min(1e-6))
        per_row = (weight * (out[:, REFLECTED] - target) ** 2).mean(dim=(1, 2, 3, 4))
    else:
        per_row = (w * (out[:, REFLECTED] - target) ** 2).mean(dim=(1, 2, 3, 4))
    reflected_loss = (room * per_row).sum() / room.sum().clamp_min(1e-6) * (room.mean() > 0)
    valid_loss = F.binary_cross_entropy_with_logits(out[:, VALIDITY], batch.valid)
    return direct_loss + settings.reflected_weight * reflected_loss, valid_loss, out


def evaluate(model, samples: Samples, settings: "TrainSettings", batch: int = 8) -> dict:
    """Over a split: the loss (scaled units), and the mean over rooms of each room's relative RMSE of its
    probes' SH (in radiance units; rooms differ in brightness by 1000x, so a pooled RMSE would be one
    room's), for all the light and the reflected light, against the truth (`*_truth`) and, on the rooms
    that have them, against Mitsuba's probes (`*_mitsuba`: noisy, so an upper bound)."""
    model.eval()
    errors: dict[str, list[float]] = {}

    def add(key, estimate, reference, rows=None):
        if rows is not None:
            if not rows.any():
                return
            estimate, reference = estimate[rows], reference[rows]
        err = ((estimate - reference) ** 2).reshape(-1, 3, *estimate.shape[1:]).sum(dim=(1, 2, 3, 4, 5))
        ref = (reference ** 2).reshape(-1, 3, *reference.shape[1:]).sum(dim=(1, 2, 3, 4, 5))
        errors.setdefault(key, []).extend((err / ref.clamp_min(1e-30)).sqrt().tolist())

    total, count = 0.0, 0
    with torch.no_grad():
        for b in batches(samples, np.arange(len(samples)), batch):
            if settings.direct_input == "traced":
                b = traced_direct(b)
            sh_loss, _, out = loss_terms(model, b, settings)
            total += float(sh_loss) * len(b.pick)
            count += len(b.pick)
            scale = torch.from_numpy(samples.scale[b.pick]).reshape(-1, 1, 1, 1, 1)
            out = out[:, :18] * scale
            y = b.y * scale
            if not encoding.DIRECT_SHADOWS:   # all the light: the exact direct light and the predicted reflected
                out = torch.cat([y[:, TOTAL] - y[:, REFLECTED] + out[:, REFLECTED], out[:, REFLECTED]], dim=1)
            add("all_truth", out[:, TOTAL], y[:, TOTAL])
            add("reflected_truth", out[:, REFLECTED], y[:, REFLECTED])
            rows = b.has_unbiased > 0
            u = b.unbiased * scale
            add("all_mitsuba", out[:, TOTAL], y[:, TOTAL] - y[:, REFLECTED] + u, rows)
            add("reflected_mitsuba", out[:, REFLECTED], u, rows)
    model.train()
    return {"loss": total / max(count, 1), **{k: float(np.mean(v)) for k, v in errors.items()}}


def train(model: ProbeNet, train_set: Samples, val_set: Samples, settings: TrainSettings,
          run: Path | None = None, quiet: bool = False) -> History:
    torch.manual_seed(settings.seed)
    torch.set_num_threads(settings.threads)
    rng = np.random.default_rng(settings.seed)
    optimizer = torch.optim.Adam(model.parameters(), lr=settings.learning_rate)
    steps_per_epoch = math.ceil(len(train_set) / settings.batch)
    if settings.steps:
        steps_per_epoch = min(steps_per_epoch, settings.steps)
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
        order = rng.permutation(len(train_set))[:steps_per_epoch * settings.batch]
        for batch in batches(train_set, order, settings.batch):
            if settings.direct_input == "traced":
                batch = traced_direct(batch)
            if settings.augment:
                for axis in (0, 2):
                    if rng.random() < 0.5:
                        batch = batch.mirrored(axis)
            sh_loss, valid_loss, _ = loss_terms(model, batch, settings)
            loss = sh_loss + VALIDITY_WEIGHT * valid_loss
            if settings.weight_decay > 0:
                loss = loss + settings.weight_decay * sum((p ** 2).sum() for p in model.parameters() if p.dim() > 1)
            optimizer.zero_grad()
            loss.backward()
            if settings.clip > 0:
                torch.nn.utils.clip_grad_norm_(model.parameters(), settings.clip)
            optimizer.step()
            schedule.step()
            running += float(sh_loss.detach()) * len(batch.pick)
            seen += len(batch.pick)
        metrics = evaluate(model, val_set, settings)
        history.epochs.append(epoch)
        history.train.append(running / seen)
        history.val.append(metrics["loss"])
        history.val_relative_rmse.append(metrics["all_truth"])
        history.val_metrics.append(metrics)
        history.seconds.append(time.perf_counter() - start)
        if not quiet:
            against = "  ".join(f"{k} {100 * v:.1f}%" for k, v in metrics.items() if k != "loss")
            print(f"epoch {epoch + 1}/{settings.epochs}  train {running / seen:.5f}  val {metrics['loss']:.5f}  "
                  f"{against}  ({history.seconds[-1]:.1f} s)", file=sys.stderr)
        if run:
            save_run(run, model, history, optimizer=optimizer.state_dict(), schedule=schedule.state_dict())
            if metrics["loss"] <= min(history.val):
                # the epoch the export ships: validation wanders by several points between epochs
                torch.save({"model": model.state_dict(), "history": history.__dict__, "epoch": epoch,
                            "config": model.config.to_dict()}, run / BEST)
    if run and not history.epochs:   # `--epochs 0`: the network as it starts (its inputs' own answer)
        save_run(run, model, history)
    elif run:
        plot_history(history, run / "loss.png", title=run.name)
    return history


def save_run(run: Path, model: ProbeNet, history: History, **state) -> None:
    """The run's checkpoint (the model, its config, the history and any other `state`) and history.json."""
    run.mkdir(parents=True, exist_ok=True)
    torch.save({"model": model.state_dict(), **state, "history": history.__dict__,
                "config": model.config.to_dict()}, run / "checkpoint.pt")
    (run / "history.json").write_text(json.dumps(history.__dict__, indent=1))


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
    from viewer.cli_parsing import add_data, add_out, tool_parser

    parser = tool_parser(__doc__, prog="python -m viewer.training.train")
    add_data(parser)
    add_out(parser, required=True, help="run directory (resumed if it exists)")
    parser.add_argument("--probes", type=int, default=24)
    parser.add_argument("--width", type=int, default=ProbeNetConfig.width)
    parser.add_argument("--coarse", type=int, nargs="*", default=[],
                        help="channels of the levels after the first, where wider than --width's rule; with "
                             "--init, the narrower network's weights start it and it gives their answers")
    parser.add_argument("--hidden", type=int, default=ProbeNetConfig.hidden)
    parser.add_argument("--head-layers", type=int, default=ProbeNetConfig.head_layers)
    parser.add_argument("--levels", type=int, default=ProbeNetConfig.levels)
    parser.add_argument("--without-seen", action="store_true",
                        help="zero the seen-bounce features (to measure what the seen rays bring)")
    parser.add_argument("--start-gains", type=float, nargs=2, metavar=("BOUNCE", "SEEN"),
                        default=(ProbeNetConfig.bounce_gain, ProbeNetConfig.seen_gain),
                        help="the reflected light's start: the unshadowed bounce's and the filtered seen "
                             "light's gains")
    parser.add_argument("--no-unshadowed", action="store_true",
                        help="keep the unshadowed bounce's gain at 0 (it passes through walls): it enters "
                             "only as the seen light's detail; a fine-tune moves its gain to the seen light")
    parser.add_argument("--no-reflected-correction", action="store_true",
                        help="the reflected light is the bounces times their gains alone (the seen one "
                             "filtered): the head corrects the direct light only")
    parser.add_argument("--no-direct-correction", action="store_true",
                        help="train without the head's correction of the direct light, the sink that keeps "
                             "the direct input's error out of the reflected light (left out at inference)")
    parser.add_argument("--epochs", type=int, default=TrainSettings.epochs)
    parser.add_argument("--batch", type=int, default=TrainSettings.batch, help="scenes per step")
    parser.add_argument("--lr", type=float, default=TrainSettings.learning_rate)
    parser.add_argument("--weight-decay", type=float, default=0.0)
    parser.add_argument("--clip", type=float, default=TrainSettings.clip, help="largest gradient norm a step takes")
    parser.add_argument("--limit", type=int, default=0,
                        help="use only the first N procedural training rooms (the paper's training layouts "
                             "are always used): a run comparable with one on a smaller dataset of the same seed")
    parser.add_argument("--steps", type=int, default=0, help="steps per epoch (0: the whole split)")
    parser.add_argument("--reflected-weight", type=float, default=TrainSettings.reflected_weight)
    parser.add_argument("--solver-weight", type=float, default=TrainSettings.solver_weight)
    parser.add_argument("--no-mitsuba", action="store_true",
                        help="reflected light against the solver's probes in every room, never Mitsuba's")
    parser.add_argument("--reflected-loss", choices=("local", "reflected", "room", "rmse"),
                        default=TrainSettings.reflected_loss)
    parser.add_argument("--init", type=Path, help="start from this checkpoint's weights (a fine-tune)")
    parser.add_argument("--threads", type=int, default=TrainSettings.threads)
    parser.add_argument("--direct-input", choices=("encoded", "traced"), default="encoded")
    parser.add_argument("--encoded-only", action="store_true",
                        help="train on the shards encoded so far (a dataset still being made)")
    parser.add_argument("--val-rooms", type=int, default=100, help="validation rooms scored every epoch")
    args = parser.parse_args(argv)
    train_set = training_split(args.data, args.probes, encode=not args.encoded_only, limit=args.limit)
    val_set = load_split(args.data, "val", args.probes)
    val_set = val_set.subset(np.arange(min(args.val_rooms, len(val_set))))
    record_data(args.out, args.data, train_set, val_set, args.probes,
                " ".join(["python -m viewer.training.train", *(sys.argv[1:] if argv is None else argv)]))
    config = ProbeNetConfig(width=args.width, coarse=args.coarse, hidden=args.hidden,
                            head_layers=args.head_layers, levels=args.levels,
                            seen=not args.without_seen, bounce_gain=args.start_gains[0],
                            seen_gain=args.start_gains[1], reflected_correction=not args.no_reflected_correction,
                            direct_correction=not args.no_direct_correction, unshadowed=not args.no_unshadowed)
    model = ProbeNet(config)
    if args.init and not (args.out / "checkpoint.pt").exists():
        init = torch.load(args.init, weights_only=False)
        model.load_unshadowed(init["model"], narrowing_activity(init, model, args.probes))
    print(f"ProbeNet {config}: {parameter_count(model)} parameters, {len(train_set)} training scenes",
          file=sys.stderr)
    settings = TrainSettings(epochs=args.epochs, batch=args.batch, learning_rate=args.lr,
                             weight_decay=args.weight_decay, steps=args.steps, threads=args.threads, clip=args.clip,
                             reflected_weight=args.reflected_weight, solver_weight=args.solver_weight,
                             mitsuba=not args.no_mitsuba, reflected_loss=args.reflected_loss, direct_input=args.direct_input)
    train(model, train_set, val_set, settings, run=args.out)
    return 0


def narrowing_activity(init: dict, model: ProbeNet, probes: int) -> dict | None:
    """Where the checkpoint `init` has wider layers than `model`: its channels' activity (`channel_activity`)
    on the Cornell box and three of the paper's training layouts, by which `narrowed` keeps them; else None."""
    if not narrows(init["model"], model.state_dict()):
        return None
    from viewer.scene import load

    wide = ProbeNet(ProbeNetConfig(**init["config"]))
    wide.load_state_dict(init["model"])
    scenes = [torch.from_numpy(encoding.encode_scene(load(name), probes, ENCODING_VOXELS).inputs)
              for name in ("cornell", "paper-train-1", "paper-train-2", "paper-train-3")]
    return channel_activity(wide, scenes)


def record_data(run: Path, data: Path, train_set: Samples, val_set: Samples, probes: int,
                command: str | None = None) -> None:
    """`run/data.json`: what the run trains on, and the command that trained it (the export copies both
    onto the model card). A resumed run with more rooms (the dataset grew) records the latest count."""
    from viewer.training.samples import ENCODING_VOXELS

    manifest = Path(data) / "manifest.json"
    settings = json.loads(manifest.read_text()).get("settings", {}) if manifest.exists() else {}
    record = {"data": str(data), "training_rooms": len(train_set), "validation_rooms": len(val_set),
              "rooms_with_mitsuba_probes": int(np.sum(train_set.has_unbiased)) if train_set.has_unbiased is not None else 0,
              "ranges": settings.get("ranges", "v1"), "truth": settings.get("truth"), "seed": settings.get("seed"),
              "probes": probes, "voxels": ENCODING_VOXELS, **({"command": command} if command else {})}
    run.mkdir(parents=True, exist_ok=True)
    (run / "data.json").write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    raise SystemExit(main())
