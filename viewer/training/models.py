"""The production network: ProbeNet, a small 3D U-Net from the encoded probe lattice to the probes' SH.

Input (B, CHANNELS, M, M, M) from `viewer.neural.encoding.encode` (B = 3 x scenes: one monochrome problem per
colour channel); output (B, OUTPUTS, M, M, M) in units of the encoding's scale: 9 SH coefficients of
all the incident radiance (`sample`, the comparisons with Mitsuba), 9 of the light reflected by
surfaces alone (what the renderer's probes hold: it shades emitters and the sun itself), and one logit
for "this probe is valid" (outside solid geometry).

Why this shape:
- Light is not local: the lamp on the ceiling lights the floor sixteen probes away and a wall's colour
  bleeds across the room. Three stride-2 levels and a global code give every probe a view of the whole
  scene at a cost of a few thousand cells.
- Shadows and contact are local: the finest level keeps each probe's own cell and its neighbours.
- The head is per probe (1x1x1 convolutions): cheap at 16^3 = 4096 probes, and the same weights work
  for any lattice size divisible by 2^levels.
- The shadowed direct light, its bounces gathered unshadowed and seen through exact rays are
  inputs (`viewer.neural.encoding`), and the head's outputs are corrections to them: the reflected
  light (9 SH) on top of the seen bounces, and in training what the direct input missed (9 SH), each
  times a learned gain, the seen one through a learned 3x3x3 filter per coefficient (it starts as the
  box filter: a few rays a probe are noisy, and the finest level of the network is otherwise per probe),
  which stops at walls: a tap across a surface takes the probe's own light (`walled_filter`, trained as
  the viewer runs it: viewer.neural.network_feed.WallTaps). The corrections are relative
  (times the local light, `MAGNITUDE_FLOOR`) and the convolutions read the light through asinh
  (`compress`): the light spans five orders of magnitude within a room. All the light is their sum, so
  the two outputs the renderer and `sample` read never disagree.

The paper's five families, for its Table 1, are in `viewer.training.paper_models`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from viewer.neural import encoding
from viewer.neural.network_feed import tap_sources
from viewer.neural.network_tail import DETAIL_FLOOR, DETAIL_MAX, REFLECTED_FLOOR


BOUNCE_GAIN, SEEN_GAIN = 0.0, 1.0
"""The reflected light's start (`ProbeNetConfig.bounce_gain`, `seen_gain`): the seen light alone,
through the box filter (learned from there). The unshadowed bounce passes through walls: started at half
of it and half the seen light, the version-6 model kept 0.4 of it and ended no better on the reflected
light than the box-filtered seen light alone (33.8-34.0% against 33.2% on 60 validation rooms); started
from the seen light, the same recipe ends at 32.2-32.5% (docs/TRAINING.md)."""


@dataclass(frozen=True)
class ProbeNetConfig:
    width: int = 16
    """Channels of the first coarse level (M/2); each coarser level doubles them (capped at 4x)."""
    coarse: tuple = ()
    """Channels of the levels after the first (M/4, M/8, ...) where they differ from `width`'s rule: the
    coarse levels cost little (a 6^3 lattice has 1/64 of the probes), so they can be wider than the
    first level, which reads every probe."""
    hidden: int = 16
    """Width of the per-probe head."""
    head_layers: int = 2
    """Layers of the per-probe head after the sum of the levels."""
    levels: int = 3
    """Stride-2 levels below the probe lattice (M must be divisible by 2^levels)."""
    upsample: str = "trilinear"
    """How a coarse level reaches the finer one: `trilinear` or `nearest` (cheaper, blockier)."""
    bounce_gain: float = BOUNCE_GAIN
    """The unshadowed bounce's gain in the reflected light at the start of training (learned from there)."""
    seen_gain: float = SEEN_GAIN
    """The filtered seen light's gain at the start of training (learned from there)."""
    reflected_correction: bool = True
    """Whether the head corrects the reflected light; without, the reflected light is the two bounces
    times their gains alone (the seen one through its learned filter): a linear denoiser of the seen
    light, and the head corrects the direct light and answers the validity only."""
    direct_correction: bool = True
    """Whether the head fits a correction of the direct light in training (9 SH, added to all the light
    the loss scores). It is a sink, left out at inference (`eval()`, and so in every export): all the
    light a network gives is the direct input plus the reflected light. With the lamps' pieces in the
    input (encoding version 8) the correction made the direct light worse than the input alone between
    the probes (a validation room 6.4% -> 10.8%, a dark room 9.9% -> 12.6% against Mitsuba, relative to
    all the light); trained without it, the reflected light takes up the direct input's error instead:
    the same error at free-space points, but images 0.8-0.9 dB further from Mitsuba's (38.3-38.5 dB
    against 39.2-39.3) and 1% darker."""
    unshadowed: bool = True
    """Whether the reflected light takes the unshadowed bounce itself, times `bounce_gain`; without, that
    gain stays 0 and the unshadowed gather enters only as the seen light's detail, scaled by what the
    rays let through (`detail_gain`). It passes through walls: with its learned gain 0.087 the doorway's
    dark room got 1.24x its true light, 1.07x with the gain moved to the seen light."""
    seen: bool = True
    """Whether the network reads the seen bounce (viewer/neural/seen.py); without it, those features are
    zeroed as they come in: the same network blind to visibility beyond the direct light's shadows
    (to measure what the seen rays bring)."""

    def __post_init__(self):
        object.__setattr__(self, "coarse", tuple(int(c) for c in self.coarse))
        if self.coarse and len(self.coarse) != self.levels - 1:
            raise ValueError(f"{len(self.coarse)} coarse widths for {self.levels - 1} levels after the first")

    def widths(self) -> list[int]:
        """The channels of each level below the lattice, the first (M/2) first."""
        rule = [self.width * min(2 ** level, 4) for level in range(self.levels)]
        return rule[:1] + list(self.coarse) if self.coarse else rule

    def to_dict(self) -> dict:
        return asdict(self)


class ProbeNet(nn.Module):
    """Coarse levels see far, the per-probe head sees near.

    Encoder: each level halves the lattice with a 2x2x2 stride-2 convolution (a learned pooling: every
    fine cell is read once) and mixes neighbours with a 3x3x3 one. Decoder: each level is projected to
    `hidden` channels at its own resolution, added to the upsampled coarser sum, and the full-resolution
    sum meets the probe's own cell features in a small per-probe head. Only `hidden` channels are ever
    upsampled, so the work at full resolution is a few small matrices per probe whatever the widths of
    the coarse levels (upsampling is the costliest operator in onnxruntime here)."""

    def __init__(self, config: ProbeNetConfig = ProbeNetConfig()):
        super().__init__()
        self.config = config
        h = config.hidden
        widths = [encoding.CHANNELS] + config.widths()
        self.down = nn.ModuleList(
            nn.Sequential(nn.Conv3d(widths[i], widths[i + 1], 2, stride=2), nn.ReLU(),
                          nn.Conv3d(widths[i + 1], widths[i + 1], 3, padding=1), nn.ReLU())
            for i in range(config.levels))
        self.project = nn.ModuleList(nn.Conv3d(widths[i + 1], h, 1) for i in range(config.levels))
        self.code = nn.Linear(widths[-1], h, bias=False)
        self.local = nn.Conv3d(encoding.CHANNELS, h, 1)
        layers: list[nn.Module] = []
        for _ in range(config.head_layers - 1):
            layers += [nn.Conv3d(h, h, 1), nn.ReLU()]
        layers.append(nn.Conv3d(h, encoding_outputs(), 1))
        self.head = nn.Sequential(*layers)
        nn.init.zeros_(self.head[-1].weight)  # start from "the direct light, and the bounces times gains"
        nn.init.zeros_(self.head[-1].bias)
        self.bounce_gain = nn.Parameter(torch.tensor(float(config.bounce_gain)))
        self.seen_gain = nn.Parameter(torch.tensor(float(config.seen_gain)))
        if not config.unshadowed:
            self.bounce_gain.requires_grad_(False)
            with torch.no_grad():
                self.bounce_gain.zero_()
        # the seen bounce's denoiser at the probes' own resolution: one 3x3x3 kernel per SH coefficient,
        # starting as the box filter (which takes its raw 62% to 30% on the validation rooms), each
        # probe weighted by its open share and the sum divided by the neighbourhood's (a normalized
        # convolution: a probe by a wall no longer averages in the dark of the probes inside it)
        self.seen_filter = nn.Conv3d(9, 9, 3, padding=1, padding_mode="replicate", groups=9, bias=False)
        nn.init.constant_(self.seen_filter.weight, 1.0 / 27.0)

    def forward(self, x: torch.Tensor, x_in: torch.Tensor | None = None,
                links: torch.Tensor | None = None) -> torch.Tensor:
        """`x` the encoded inputs; `x_in` the same through `compress` where the caller made it already
        (the exported network takes it as its second input: `encoding.compressed`); `links` (rooms, 3, M,
        M, M) where the seen filter stops (the rooms' three colour passes are consecutive rows of `x`:
        `walled_taps`), as the viewer stops it (viewer.neural.network_feed.WallTaps)."""
        if not self.config.seen:
            x = torch.cat([x[:, :encoding.SEEN.start], torch.zeros_like(x[:, encoding.SEEN]), x[:, encoding.SEEN.stop:]],
                          dim=1)
        direct_dc = x[:, encoding.DIRECT.start:encoding.DIRECT.start + 1]
        bounce_dc = x[:, encoding.BOUNCE.start:encoding.BOUNCE.start + 1]
        seen_dc = F.avg_pool3d(x[:, encoding.SEEN.start:encoding.SEEN.start + 1], 3, stride=1, padding=1,
                               count_include_pad=False)
        reflected_magnitude = 0.5 * (bounce_dc.abs() + seen_dc.abs()) + REFLECTED_FLOOR
        opened = x[:, encoding.OPEN:encoding.OPEN + 1]
        x_in = compress(x) if x_in is None else x_in
        levels = []
        level = x_in
        for down in self.down:
            level = down(level)
            levels.append(level)
        hidden = self.project[-1](level) + self.code(level.mean(dim=(2, 3, 4)))[:, :, None, None, None]
        for i in range(len(levels) - 2, -1, -1):
            hidden = self.project[i](levels[i]) + self._up(hidden)
        hidden = F.relu(self.local(x_in) + self._up(hidden))
        out = self.head(hidden)
        bounce = x[:, encoding.BOUNCE]
        if links is None:
            seen = self.seen_filter(x[:, encoding.SEEN] * opened)
            weight = F.avg_pool3d(F.pad(opened, (1,) * 6, mode="replicate"), 3, stride=1).clamp_min(1.0 / 27.0)
            smooth = self.seen_filter(bounce * opened)
        else:
            taps = walled_taps(links, x.shape[0] // links.shape[0])
            seen = walled_filter(self.seen_filter.weight, x[:, encoding.SEEN] * opened, taps)
            weight = walled_filter(torch.full((1, 1, 3, 3, 3), 1.0 / 27.0), opened, taps).clamp_min(1.0 / 27.0)
            smooth = walled_filter(self.seen_filter.weight, bounce * opened, taps)
        smooth = smooth / weight
        seen = seen / weight
        seen = seen + detail_gain(seen, smooth) * (bounce - smooth)
        reflected = self.bounce_gain * bounce + self.seen_gain * seen
        if self.config.reflected_correction:
            reflected = reflected + out[:, REFLECTED] * reflected_magnitude
        total = x[:, encoding.DIRECT] + reflected
        if self.config.direct_correction and self.training:   # the sink for the direct input's error
            total = total + out[:, TOTAL] * (direct_dc.abs() + bounce_dc.abs() + MAGNITUDE_FLOOR)
        return torch.cat([total, reflected, out[:, VALIDITY:]], dim=1)

    def load_unshadowed(self, state: dict, activity: dict[str, torch.Tensor] | None = None) -> None:
        """Load `state` (a state dict, of this network or of a narrower one: `widened`); where this network
        takes no unshadowed bounce, that bounce's learned gain is moved to the seen light, which carries
        the same light with visibility. A state with wider levels or head is cut to this one's (`narrowed`, by
        the wide network's `activity`)."""
        own = self.state_dict()
        self.load_state_dict(widened(narrowed(state, own, activity), own))
        if not self.config.unshadowed:
            with torch.no_grad():
                self.seen_gain += self.bounce_gain
                self.bounce_gain.zero_()

    def _up(self, x: torch.Tensor) -> torch.Tensor:
        if self.config.upsample == "nearest":
            return F.interpolate(x, scale_factor=2, mode="nearest")
        return F.interpolate(x, scale_factor=2, mode="trilinear", align_corners=False)


def widened(state: dict, wide: dict) -> dict:
    """`state` (a state dict) grown to the shapes of `wide` (another ProbeNet's, whose levels have as many
    channels or more) computing the same function: each weight keeps its values in its leading block;
    a channel it lacked starts as `wide` has it (the new network's random start), except that the channels
    `state` had take nothing from the new ones (those weights are zero). So the wider network starts
    as the narrower one's answers, and training finds a use for the new channels: their outgoing weights
    have gradients as soon as they carry anything."""
    if state.keys() != wide.keys():
        differ = sorted(set(state) ^ set(wide))
        raise ValueError(f"not the same layers: {', '.join(differ[:4])}{' ...' if len(differ) > 4 else ''}")
    out = {}
    for name, value in wide.items():
        old = state[name]
        if tuple(old.shape) == tuple(value.shape):
            out[name] = old
            continue
        if old.dim() != value.dim() or any(a > b for a, b in zip(old.shape, value.shape)):
            raise ValueError(f"{name}: {tuple(old.shape)} cannot grow to {tuple(value.shape)}")
        grown = value.clone()
        if old.dim() >= 2:
            grown[:old.shape[0], old.shape[1]:] = 0.0   # the kept outputs ignore the new inputs
        grown[tuple(slice(0, n) for n in old.shape)] = old
        out[name] = grown
    return out


def hidden_layers(state: dict) -> list[tuple[str, list[str], list[str], str]]:
    """The hidden layers of a ProbeNet of state dict `state`, each as (name, the parameters that make its
    channels (along their first axis), the weights that read them (along their second axis), the module
    whose input they are): each level's two convolutions, the sum of the levels and the probe's own
    features, and the head's hidden layers."""
    levels = sum(1 for k in state if k.startswith("down.") and k.endswith(".0.weight"))
    convs = sorted((k[:-len(".weight")] for k in state if k.startswith("head.") and k.endswith(".weight")),
                   key=lambda k: int(k.split(".")[1]))
    layers = []
    for i in range(levels):
        layers.append((f"down.{i}.0", [f"down.{i}.0.weight", f"down.{i}.0.bias"], [f"down.{i}.2.weight"],
                       f"down.{i}.2"))
        after = [f"project.{i}.weight"] + ([f"down.{i + 1}.0.weight"] if i + 1 < levels else ["code.weight"])
        layers.append((f"down.{i}.2", [f"down.{i}.2.weight", f"down.{i}.2.bias"], after, f"project.{i}"))
    sums = ["local.weight", "local.bias", "code.weight"] + [f"project.{i}.{part}" for i in range(levels)
                                                              for part in ("weight", "bias")]
    layers.append(("sum", sums, [f"{convs[0]}.weight"], convs[0]))
    for layer, after in zip(convs[:-1], convs[1:]):
        layers.append((layer, [f"{layer}.weight", f"{layer}.bias"], [f"{after}.weight"], after))
    return layers


def narrows(state: dict, narrow: dict) -> bool:
    """Whether `narrow` (a ProbeNet's state dict) has the layers of `state` with some narrower and none wider:
    what `narrowed` cuts `state` to."""
    return state.keys() == narrow.keys() and all(
        state[k].dim() == narrow[k].dim() and all(a >= b for a, b in zip(state[k].shape, narrow[k].shape))
        for k in state) and any(tuple(state[k].shape) != tuple(narrow[k].shape) for k in state)


def narrowed(state: dict, narrow: dict, activity: dict[str, torch.Tensor] | None = None) -> dict:
    """`state` (a ProbeNet's state dict) cut to the narrower levels or head of `narrow` (a ProbeNet's of as
    many levels and head layers, no layer wider; else `state` as it is, for `widened`). Each hidden layer
    keeps the channels that carry the most into the next: the mean size of a channel's activation
    (`activity`: `channel_activity` of the wide network; without it, the norm of its incoming weights and
    bias) times the norm of its outgoing weights. Not the same function, but a start a fine-tune recovers
    from in a few epochs, where a narrower network trained afresh would repeat the whole training."""
    if not narrows(state, narrow):
        return state
    out = dict(state)
    for name, makers, readers, _ in hidden_layers(state):
        channels, wanted = state[makers[0]].shape[0], narrow[makers[0]].shape[0]
        if wanted == channels:
            continue
        incoming = torch.cat([state[k].reshape(channels, -1) for k in makers], 1)
        size = incoming.norm(dim=1) if activity is None else activity[name]
        outgoing = torch.cat([state[k].transpose(0, 1).reshape(channels, -1) for k in readers], 1)
        kept = torch.sort(torch.topk(size * outgoing.norm(dim=1), wanted).indices).values
        for k in makers:
            out[k] = out[k][kept]
        for k in readers:
            out[k] = out[k][:, kept]
    differ = [name for name, value in narrow.items() if tuple(out[name].shape) != tuple(value.shape)]
    if differ:
        raise ValueError(f"not only narrower layers: {', '.join(differ[:4])}{' ...' if len(differ) > 4 else ''}")
    return out


def channel_activity(model: "ProbeNet", inputs: list[torch.Tensor]) -> dict[str, torch.Tensor]:
    """The mean |activation| of each channel of each of `model`'s hidden layers (`hidden_layers`) over
    encoded `inputs` (each (B, CHANNELS, M, M, M)): what `narrowed` keeps the largest of."""
    layers = [(name, model.get_submodule(module)) for name, _, _, module in hidden_layers(model.state_dict())]
    sums = {name: torch.zeros(module.in_channels) for name, module in layers}

    def seen(name: str):
        def hook(_, given, __) -> None:
            sums[name].add_(given[0].abs().mean(dim=(0, 2, 3, 4)))
        return hook

    hooks = [module.register_forward_hook(seen(name)) for name, module in layers]
    try:
        with torch.no_grad():
            for x in inputs:
                model.eval()(x)
    finally:
        for hook in hooks:
            hook.remove()
    return {name: total / max(len(inputs), 1) for name, total in sums.items()}


def walled_taps(links: torch.Tensor, passes: int) -> torch.Tensor:
    """(rooms x passes, 27, M^3) int64: the probe each of the 27 taps of each probe takes
    (viewer.neural.network_feed.tap_sources) in each room of `links` (rooms, 3, M, M, M), repeated for its
    `passes` rows."""
    taps = np.stack([tap_sources(room.numpy()) for room in links])
    return torch.from_numpy(taps).repeat_interleave(passes, dim=0)


def walled_filter(kernels: torch.Tensor, light: torch.Tensor, taps: torch.Tensor) -> torch.Tensor:
    """(B, C, M, M, M): `light` (B, C, M, M, M) filtered with the 3x3x3 `kernels` (C or 1, 1, 3, 3, 3: the
    grouped Conv3d's weight) over the probes `taps` (B, 27, M^3) gives each tap (`walled_taps`): the
    grouped convolution with replicate padding where no tap crosses a wall."""
    b, c = light.shape[:2]
    flat = light.reshape(b, c, -1)
    weights = kernels.reshape(kernels.shape[0], 27)
    out = torch.zeros_like(flat)
    for t in range(27):
        out = out + weights[:, t, None] * flat.gather(2, taps[:, t, None, :].expand(b, c, -1))
    return out.reshape(light.shape)


TOTAL, REFLECTED, VALIDITY = slice(0, 9), slice(9, 18), 18
MAGNITUDE_FLOOR = 0.1
"""The head's corrections are relative: the direct light's times |direct DC| + |bounce DC| + this (in
the encoding's units, where the room's mean direct DC is 1), so one output unit is a tenth of a dim
corner's light and a tenth of a lamp's neighbour's, and the loss (relative near the lamps) asks for
outputs of one size."""


def detail_gain(seen: torch.Tensor, smooth: torch.Tensor) -> torch.Tensor:
    """(B, 1, M, M, M): how much of the unshadowed gather's fine detail the filtered seen light takes: the
    share of the unshadowed light (filtered as the seen light is, `smooth`) that the rays see, per probe
    (DC ratio). The seen light's filter blurs 3x3x3 probes; the unshadowed gather of the same surfaces is
    exact between them but passes through walls; its detail (itself less its filtered self) scaled by
    what the rays let through restores what the blur took where the visibility is smooth (a ratio
    estimator: on the solver's converged light the public scenes' indirect error falls from 9.6% to
    8.2%, on the encoding's own surface light from 10.6% to 9.8%)."""
    return (seen[:, :1] / smooth[:, :1].clamp_min(DETAIL_FLOOR)).clamp(0.0, DETAIL_MAX)


def compress(x: torch.Tensor) -> torch.Tensor:
    """The inputs as the convolutions read them: the light (emission, direct light, the bounces:
    `encoding.COMPRESSED`) through asinh. It spans five orders of magnitude (a probe next to a lamp sees
    ~300x the room's mean, the far corner a hundredth of it); raw, the few cells by the lamps are all
    that the first layers' activations hold. `encoding.compressed` is the same in numpy."""
    parts, start = [], 0
    for part in encoding.COMPRESSED:
        parts += [x[:, start:part.start], asinh(x[:, part])]
        start = part.stop
    return torch.cat(parts + ([x[:, start:]] if start < x.shape[1] else []), dim=1)


def asinh(t: torch.Tensor) -> torch.Tensor:
    """torch.asinh in operators the ONNX exporter knows (it has no aten::asinh), odd-symmetric so that
    large negative coefficients keep their precision."""
    return torch.sign(t) * torch.log(t.abs() + torch.sqrt(t * t + 1.0))
OUTPUTS = 19


def encoding_outputs() -> int:
    return OUTPUTS


def parameter_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
