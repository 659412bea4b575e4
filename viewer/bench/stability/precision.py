"""Precision: very bright emitters through the renderer's RGBA16F probe textures.

Half floats stop at 65504. The study lights the closed room with a lamp of radiance 1e2 ... 1e6 (and a
very dim one), solves, and packs the probe grid the way the renderer uploads it
(viewer.gpu.probe_textures.texel_volumes: one power-of-two scale per grid), and the way it did before
that scale existed (each coefficient clipped to +-65504). It decodes the texels as the shader does
(divided by the weight in the last alpha) and compares the irradiance at the six axis normals with the
float32 grid: Inf or NaN texels, black probes (light in float32, none after packing), probes that turn
negative, and the largest irradiance error relative to the probe's mean irradiance. Through GL when a
context can be made (the driver's own float-to-half conversion), else with numpy's.
"""

from __future__ import annotations

import numpy as np

from viewer.physical import gi
from viewer.bench.stability import scenes
from viewer.bench.stability.common import RunConfig, StudyResult, axis_irradiance, try_method
from viewer.bench.stability.methods import MethodSettings, MethodUnavailable, gl_context
from viewer.probes.grid import ProbeGrid

COLUMNS = [("radiance", "lamp radiance", "{:.0e}"), ("light", "light", "{}"), ("method", "method", "{}"),
           ("packing", "packing", "{}"), ("largest", "largest coefficient", "{:.3g}"),
           ("nonfinite", "Inf/NaN texels", "{:d}"), ("black", "black probes", "{:.3f}"),
           ("negative", "probes turned negative", "{:.3f}"), ("error", "max irradiance error", "{:.2e}")]
HALF_MAX = float(np.finfo(np.float16).max)


def clipped_volumes(grid: ProbeGrid) -> list[np.ndarray]:
    """The packing before the per-grid scale: every texel clipped to the half-float range."""
    return [np.clip(v, -HALF_MAX, HALF_MAX).astype(np.float16) for v in grid.texture_data()]


def scaled_volumes(grid: ProbeGrid, through_gl: bool) -> list[np.ndarray]:
    """The renderer's packing, read back from real RGBA16F textures when `through_gl`."""
    from viewer.gpu.probe_textures import ProbeTextures, texel_volumes

    if not through_gl:
        return texel_volumes(grid, "f2")[0]
    textures = ProbeTextures(gl_context(), grid)
    try:
        m = grid.resolution
        return [np.frombuffer(t.read(), np.float16).reshape(m, m, m, 4) for t in textures.textures]
    finally:
        textures.release()


def decode(volumes: list[np.ndarray]) -> np.ndarray:
    """Texels -> SH (M^3, 9, 3) as probe_grid.glsl reads a texel centre: divided by its weight (alpha)."""
    flat = np.concatenate([v.astype(np.float64) for v in volumes], axis=-1)      # [z, y, x, 28]
    with np.errstate(divide="ignore", invalid="ignore"):
        coefficients = flat[..., :27] / flat[..., 27:]
    return coefficients.transpose(2, 1, 0, 3).reshape(-1, 9, 3)                   # back to [x, y, z]


def compare(grid: ProbeGrid, volumes: list[np.ndarray]) -> dict:
    exact = axis_irradiance(grid.coefficients.reshape(-1, 9, 3)).mean(axis=-1)   # (P, 6)
    packed_sh = decode(volumes)
    finite = np.isfinite(packed_sh).all(axis=(1, 2))
    packed = axis_irradiance(np.where(finite[:, None, None], packed_sh, 0.0)).mean(axis=-1)
    scale = np.maximum(np.abs(exact).mean(axis=1), 1e-30)
    lit = exact.max(axis=1) > 0
    return dict(nonfinite=int(sum((~np.isfinite(v.astype(np.float32))).sum() for v in volumes)),
                black=float((lit & (~finite | (packed.max(axis=1) <= 0))).mean()),
                negative=float(((exact.min(axis=1) >= 0) & (packed.min(axis=1) < 0)).mean()),
                error=float(np.nanmax(np.where(finite[:, None], np.abs(packed - exact), np.inf) / scale[:, None])))


def run(config: RunConfig) -> StudyResult:
    result = StudyResult("precision", COLUMNS)
    radiances = (1e2, 1e4, 1e5, 1e6) if config.quick else (1e-3, 1e2, 1e3, 1e4, 1e5, 3e5, 1e6)
    settings = gi.GISettings(voxels=16, probes=12, directions=128)
    try:
        gl_context()
        through_gl = True
    except MethodUnavailable as exc:
        through_gl = False
        result.notes.append(f"packed with numpy, not through GL: {exc}")
    methods = [m for m in config.methods if m in ("solver", "compute")]
    for radiance in radiances:
        scene = scenes.lit_room(radiance=radiance, name=f"lit-room-{radiance:g}")
        for include_emitted in (False, True):
            light = "indirect (renderer)" if not include_emitted else "incident"
            for name in methods:
                grid = try_method(name, scene, MethodSettings(settings, include_emitted), result)
                if grid is None:
                    continue
                largest = float(np.abs(grid.coefficients).max())
                for packing, volumes in (("clip (before)", clipped_volumes(grid)),
                                         ("scaled (now)", scaled_volumes(grid, through_gl))):
                    result.rows.append(dict(radiance=radiance, light=light, method=name, packing=packing,
                                            largest=largest, **compare(grid, volumes)))
                print(f"precision {radiance:g} {light} {name}: largest {largest:.3g}, "
                      f"error clip {result.rows[-2]['error']:.2e} scaled {result.rows[-1]['error']:.2e}", flush=True)
    result.notes.append(f"{settings.voxels}^3 voxels, {settings.probes}^3 probes, {settings.directions} directions; "
                        "the closed lit room with its 0.6 x 0.6 lamp. Error: max over probes and the six axis "
                        "normals of |E(packed) - E(float32)| / the probe's mean |E|.")
    summarize(result)
    return result


def summarize(result: StudyResult) -> None:
    for packing in ("clip (before)", "scaled (now)"):
        rows = [r for r in result.rows if r["packing"] == packing and r["light"] == "indirect (renderer)"]
        if not rows:
            continue
        broken = [r for r in rows if r["nonfinite"] or r["black"] or r["negative"] or r["error"] > 0.01]
        first = min((r["radiance"] for r in broken if r["radiance"] >= 1), default=None)
        worst = max(r["error"] for r in rows)
        result.summary.append(
            f"{packing}, indirect light: " + (f"wrong from lamp radiance {first:.0e} on" if first else
                                              "no Inf, NaN, black or negative probes at any radiance")
            + f"; largest irradiance error {worst:.1e} of a probe's mean.")


def chart(result: StudyResult, path) -> None:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for packing, style in (("clip (before)", "--"), ("scaled (now)", "-")):
        for light, marker in (("indirect (renderer)", "o"), ("incident", "s")):
            rows = [r for r in result.rows if r["packing"] == packing and r["light"] == light
                    and r["method"] == result.rows[0]["method"]]
            ax.plot([r["radiance"] for r in rows], [max(r["error"], 1e-6) for r in rows], style, marker=marker,
                    label=f"{packing}, {light}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.axhline(2.0 ** -11, color="k", lw=0.8, ls=":")
    ax.text(1e-3, 2.0 ** -11 * 1.3, "half-float rounding (2^-11)", fontsize=8)
    ax.set_xlabel("lamp radiance")
    ax.set_ylabel("max irradiance error after RGBA16F packing\n(relative to the probe's mean)")
    ax.set_title(f"Probe textures vs float32 ({result.rows[0]['method']})", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
