"""SH ringing: a small bright emitter, seen by a probe as almost a delta, rings below zero in L2.

The L2 projection of a delta gives negative irradiance on its far side (-0.040 of the peak, viewer.probes.sh);
a probe near a small lamp sees nearly that. Measured at every probe of the grid and at free-space points,
over 4096 lattice normals each, for the full incident light (`sample`) and the indirect light only (what
the renderer shades from the probes; it clamps negative irradiance to 0, i.e. black), without deringing
and with the deringing window (`GISettings.dering`, viewer.probes.sh.dering, the poussin window: strength 1
guarantees non-negative irradiance for non-negative radiance, at the cost of blurring band 1 by half).

The deringing is applied to each method's grid as the product does it, after projection and fill
(viewer.probes.grid.project), so one solve serves every strength. Mitsuba's probes show the ringing that the
truncation to L2 itself causes: no method can do better without deringing.
"""

from __future__ import annotations

import numpy as np

from viewer.physical import gi
from viewer.probes import sh
from viewer.evaluation.points import free_space_points
from viewer.bench.stability import scenes
from viewer.bench.stability.common import RunConfig, StudyResult, style, try_method
from viewer.bench.stability.methods import MethodSettings

COLUMNS = [("emitter", "emitter", "{}"), ("light", "light", "{}"), ("method", "method", "{}"),
           ("dering", "dering", "{:.2f}"), ("probes_negative", "probes with E < 0", "{:.3f}"),
           ("normals_negative", "(probe, normal) pairs with E < 0", "{:.4f}"),
           ("worst", "min E / mean E (probes)", "{:+.4f}"), ("points_negative", "points with E < 0", "{:.3f}"),
           ("blur", "band-1 kept", "{:.2f}")]
SMALL = "small bright (0.1 x 0.1, L = 500)"
EMITTERS = {SMALL: dict(half_size=0.05, radiance=500.0), "large (0.6 x 0.6, L = 5)": dict(half_size=0.3, radiance=5.0)}
STRENGTHS = (0.0, 0.5, 1.0)
CURVE_STRENGTHS = np.linspace(0.0, 1.0, 11)
NORMALS = 4096
EPSILON = 1e-6
"""Irradiance below -EPSILON x the probe's mean irradiance counts as negative (float32 round-off)."""


def negative_irradiance(coefficients: np.ndarray, normals: int = NORMALS, chunk: int = 1024) -> dict:
    """Statistics of negative irradiance over many normals for SH (P, 9, 3), using the mean of RGB."""
    grey = np.asarray(coefficients, np.float64).mean(axis=-1)                 # (P, 9)
    mean = np.maximum(np.pi * 0.282095 * grey[:, 0], 1e-30)                  # mean E over all normals
    directions, _ = sh.sphere_directions(normals)
    lobe = (sh.basis(directions) * sh.COSINE_LOBE).T                         # (9, N)
    any_negative, negative_pairs, worst = np.zeros(len(grey), bool), 0, np.inf
    for start in range(0, len(grey), chunk):
        e = grey[start:start + chunk] @ lobe                                   # (p, N)
        negative = e < -EPSILON * mean[start:start + chunk, None]
        any_negative[start:start + chunk] = negative.any(axis=1)
        negative_pairs += int(negative.sum())
        worst = min(worst, float((e.min(axis=1) / mean[start:start + chunk]).min()))
    return dict(probes_negative=float(any_negative.mean()), normals_negative=negative_pairs / (len(grey) * normals),
                worst=worst)


def run(config: RunConfig) -> StudyResult:
    result = StudyResult("ringing", COLUMNS)
    settings = gi.GISettings(voxels=16, probes=12 if config.quick else 16, directions=256)
    emitters = dict(list(EMITTERS.items())[:1]) if config.quick else EMITTERS
    methods = [m for m in config.methods if m not in ("ambient",)]   # one DC term cannot ring
    for label, emitter in emitters.items():
        scene = scenes.lit_room(**emitter, name="small-lamp" if emitter["half_size"] < 0.1 else "lit-room")
        points = free_space_points(scene, 400, margin=0.06, seed=9)
        for include_emitted in (True, False):
            light = "incident (sample)" if include_emitted else "indirect (renderer)"
            for name in methods:
                grid = try_method(name, scene, MethodSettings(settings, include_emitted), result)
                if grid is None:
                    continue
                probes = grid.coefficients.reshape(-1, 9, 3)
                at_points = grid.interpolate(points)
                if emitter is EMITTERS[SMALL]:   # the chart's curves, on a finer set of strengths
                    curves = [negative_irradiance(sh.dering(probes, x), 1024) for x in CURVE_STRENGTHS]
                    result.series[f"{name}, {light}"] = {
                        "negative": [c["probes_negative"] for c in curves], "worst": [c["worst"] for c in curves]}
                for strength in STRENGTHS:
                    factors = sh.window_factors(strength)
                    stats = negative_irradiance(sh.dering(probes, strength))
                    stats["points_negative"] = negative_irradiance(sh.dering(at_points, strength))["probes_negative"]
                    result.rows.append(dict(emitter=label, light=light, method=name, dering=strength,
                                            blur=factors[1], **stats))
                print(f"ringing {scene.name} {light} {name}: worst {result.rows[-3]['worst']:+.4f} "
                      f"-> {result.rows[-1]['worst']:+.4f}", flush=True)
    result.notes.append(f"{settings.voxels}^3 voxels, {settings.probes}^3 probes, {settings.directions} directions; "
                        f"{NORMALS} lattice normals per probe; 400 free-space points. E is the mean of RGB; a "
                        f"probe counts as negative when E < -{EPSILON:g} x its mean irradiance for some normal.")
    summarize(result)
    return result


def summarize(result: StudyResult) -> None:
    for r in result.rows:
        if r["method"] in ("solver", "mitsuba-probes") and r["emitter"].startswith("small") and r["dering"] in (0.0, 1.0):
            result.summary.append(
                f"small lamp, {r['light']}, `{r['method']}`, dering {r['dering']:g}: {100 * r['probes_negative']:.1f}% of "
                f"probes have a normal with negative irradiance, worst {r['worst']:+.3f} of the probe's mean.")


def chart(result: StudyResult, path) -> None:
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    x = CURVE_STRENGTHS
    for label, curve in result.series.items():
        method, light = label.split(", ", 1)
        keywords = dict(style(method), label=label, ms=4)
        if light.startswith("indirect"):
            keywords.update(alpha=0.5, ls="-.")
        else:
            axes[0].plot(x, [100 * v for v in curve["negative"]], **keywords)
        axes[1].plot(x, curve["worst"], **keywords)
    axes[0].set_ylabel("% of probes with negative irradiance\nfor some normal (incident light)")
    axes[1].set_ylabel("lowest irradiance over probes and normals\n/ that probe's mean irradiance")
    axes[1].axhline(0.0, color="k", lw=0.8)
    for ax in axes:
        ax.set_xlabel("deringing strength (poussin window)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("A 0.1 x 0.1 lamp of radiance 500 in the closed room", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
