"""Ground truth from Mitsuba 3: incident-radiance SH at probes, surface irradiance, path-traced images.

An independent path tracer the rest of the pipeline is measured against (docs/ARCHITECTURE.md, "Ground
truth").
Only tests, benchmarks and the command line import this module; the numpy core never does. Mitsuba is
an optional extra (`pip install mitsuba`, or `pip install gi-viewer[reference]`): importing this module
works without it, the first call says what to install.

The Mitsuba variant is chosen once, on first use: `llvm_ad_rgb` (vectorised, needs libLLVM), else
`scalar_rgb` (one Python call per sample: correct but very slow). `GI_VIEWER_MITSUBA_VARIANT` forces
one; `variant()` says which was used. The scene conversion is viewer/reference/conversion.py, loading
Mitsuba viewer/reference/runtime.py; this module is the estimators and the face the rest imports.

Estimator, for incident radiance L(p, w) at a point p (probes and surface points alike):

    L(p, w) = Le(x, -w) + Lr(x, -w),   x = the first surface seen from p along w.

The emitted part Le is estimated by light sampling (`Scene.sample_emitter_direction`), which also finds
the sun (a delta that no sampled direction ever hits) and small area lights. The reflected part Lr is the
radiance Mitsuba's path integrator returns along the ray minus the emission at its first hit, so that
Le is counted once. Directions are a spherical Fibonacci lattice turned by a random rotation per probe
(stratified and unbiased, `sh.sphere_directions`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from viewer.reference import cache as reference_cache
from viewer.reference.conversion import load_scene, to_mitsuba  # noqa: F401 - part of the face
from viewer.reference.runtime import (INSTALL_HINT, VARIANTS, ReferenceUnavailable,  # noqa: F401 - the face
                                      aligned, loaded, variant)
from viewer.probes import sh
from viewer.scene import Camera, Scene
from viewer.scene.geometry import NO_TWIN

LANES_PER_LAUNCH = 1 << 21
"""Rays traced per Dr.Jit launch; larger jobs run in batches of whole probes."""
CACHE_VERSION = "reference-v1"
"""Bump when the estimators change, so cached results computed by older code are not reused."""


# ---- incident radiance along rays -------------------------------------------------------------------

class _Lane(NamedTuple):
    """What one traced lane knows, in Mitsuba types (wide arrays, or scalars in scalar_rgb)."""

    direction: object
    """The traced direction w (from the point towards where the light comes from)."""
    reflected: object
    """Radiance arriving from w, less the emission of the surface first seen along w."""
    light_direction: object
    """Direction of the light sample."""
    light_weight: object
    """Its emitted radiance / pdf (solid angle), zero when occluded or behind a one-sided emitter."""
    normal: object
    """The lane's surface normal (irradiance), or None (probes)."""


def _estimate(mscene, origins: np.ndarray, directions: np.ndarray, terms, normals=None, seed=0):
    """Mean over each item's S lanes of `terms(dr, lane)` (a list of T per-lane estimates), tracing
    directions (B, S, 3) from origins (B, 3). Returns (B, T) float64.

    Light samples come from a randomly shifted 2D lattice per item (stratified light sampling: a
    light's area is covered evenly, not by chance). The per-item sums run in Dr.Jit (`block_sum`), so
    no per-lane array comes back to numpy."""
    mi, dr, scalar = loaded()
    count, per_item, _ = directions.shape
    k = np.arange(per_item)
    # Fibonacci lattice in the unit square ((k + 1/2)/n, k/golden) under a Cranley-Patterson shift.
    light = np.stack([(k + 0.5) / per_item, (k * _INVERSE_GOLDEN) % 1.0], axis=-1)
    light = (light[None] + np.random.default_rng([seed, 0x116]).random((count, 1, 2))) % 1.0
    lanes = {"o": np.repeat(origins, per_item, axis=0), "d": directions.reshape(-1, 3),
             "u": light.reshape(-1, 2)}
    if normals is not None:
        lanes["n"] = np.repeat(normals, per_item, axis=0)
    sampler = mi.load_dict({"type": "independent"})
    if scalar:
        return _estimate_scalar(mi, dr, mscene, sampler, lanes, per_item, terms, seed)
    sampler.seed(seed & 0x7FFFFFFF, count * per_item)

    def wide(name, kind):
        return kind(*(mi.Float(aligned(lanes[name][:, a])) for a in range(lanes[name].shape[1])))

    lane = _trace(mi, dr, mscene, sampler, wide("o", mi.Point3f), wide("d", mi.Vector3f),
                  wide("u", mi.Point2f), wide("n", mi.Vector3f) if normals is not None else None)
    # One path-tracing kernel stores the lane results; without this eval every term below would
    # re-trace the paths in its own kernel (Dr.Jit evaluates each output's whole graph).
    dr.eval(lane.reflected, lane.light_direction, lane.light_weight)
    sums = [dr.block_sum(t, per_item) for t in terms(dr, lane)]
    dr.eval(*sums)
    return np.stack([np.array(t, np.float64) for t in sums], axis=-1) / per_item


def _estimate_scalar(mi, dr, mscene, sampler, lanes, per_item, terms, seed):
    """scalar_rgb: the same estimator, one Python call per lane."""
    sampler.seed(seed & 0x7FFFFFFF)
    out = None
    for i in range(len(lanes["o"])):
        lane = _trace(mi, dr, mscene, sampler, mi.Point3f(*map(float, lanes["o"][i])),
                      mi.Vector3f(*map(float, lanes["d"][i])), mi.Point2f(*map(float, lanes["u"][i])),
                      mi.Vector3f(*map(float, lanes["n"][i])) if "n" in lanes else None)
        values = np.array([float(t) for t in terms(dr, lane)])
        if out is None:
            out = np.zeros((len(lanes["o"]) // per_item, len(values)))
        out[i // per_item] += values
        sampler.advance()
    return out / per_item


def _trace(mi, dr, mscene, sampler, o, d, light_sample, normal) -> _Lane:
    """The estimator of the module docstring, written once for wide (llvm) and scalar types."""
    total, _, _ = mscene.integrator().sample(mscene, sampler, mi.RayDifferential3f(o, d))
    first = mscene.ray_intersect(mi.Ray3f(o, d))
    emitter = first.emitter(mscene)  # an EmitterPtr (wide), or an Emitter / None (scalar)
    seen = emitter.eval(first, first.is_valid()) if emitter is not None else mi.Color3f(0.0)
    # Light sampling from the point itself (no surface there: zero normal, no offset needed).
    it = dr.zeros(mi.Interaction3f)
    it.p = o
    it.t = 0.0
    ds, weight = mscene.sample_emitter_direction(it, light_sample, True)
    return _Lane(d, total - seen, ds.d, weight, normal)


def _probe_terms(dr, lane: _Lane) -> list:
    """Per-lane estimates of the 27 c_lm (coefficient-major, RGB inner): uniform sphere directions
    (pdf 1/4pi) for the reflected part, light samples (already divided by their pdf) for emission."""
    y_ray, y_light = _basis(lane.direction), _basis(lane.light_direction)
    return [4 * np.pi * y_ray[k] * lane.reflected[c] + y_light[k] * lane.light_weight[c]
            for k in range(sh.SH_COUNT) for c in range(3)]


def _probe_part_terms(dr, lane: _Lane) -> list:
    """`_probe_terms` with the reflected and the emitted part apart: 27 + 27 estimates."""
    y_ray, y_light = _basis(lane.direction), _basis(lane.light_direction)
    return ([4 * np.pi * y_ray[k] * lane.reflected[c] for k in range(sh.SH_COUNT) for c in range(3)]
            + [y_light[k] * lane.light_weight[c] for k in range(sh.SH_COUNT) for c in range(3)])


def _irradiance_terms(dr, lane: _Lane) -> list:
    """Per-lane estimates of E (RGB): cosine-distributed directions (pdf cos/pi) for the reflected
    part, light samples weighted by the clamped cosine."""
    cosine = dr.maximum(dr.dot(lane.normal, lane.light_direction), 0.0)
    return [np.pi * lane.reflected[c] + lane.light_weight[c] * cosine for c in range(3)]


def _indirect_irradiance_terms(dr, lane: _Lane) -> list:
    """`_irradiance_terms` without the light samples: the reflected light only."""
    return [np.pi * lane.reflected[c] for c in range(3)]


def _basis(d) -> list:
    """`viewer.probes.sh.basis` in plain arithmetic, so that it runs inside a Dr.Jit kernel (same order and
    constants, docs/ARCHITECTURE.md; tests check the two agree)."""
    x, y, z = d[0], d[1], d[2]
    return [0.282095 + 0.0 * x, 0.488603 * y, 0.488603 * z, 0.488603 * x, 1.092548 * x * y,
            1.092548 * y * z, 0.315392 * (3 * z * z - 1), 1.092548 * x * z, 0.546274 * (x * x - y * y)]


def _batches(count: int, per_item: int):
    step = max(1, LANES_PER_LAUNCH // max(per_item, 1))
    for start in range(0, count, step):
        yield start, min(count, start + step)


_INVERSE_GOLDEN = 2 / (1 + 5 ** 0.5)


def _lattice(count: int, per_item: int, seed: int) -> np.ndarray:
    """(count, per_item, 3) uniform sphere directions: the Fibonacci lattice of `sh.sphere_directions`
    under an independent Haar-random rotation per item, so every direction is uniformly distributed
    (unbiased) while each item's set stays stratified."""
    base, _ = sh.sphere_directions(per_item)
    # A unit quaternion drawn from a 4D isotropic Gaussian is a uniform rotation (Shoemake 1992).
    w, x, y, z = np.random.default_rng([seed, 0x5EED]).normal(size=(4, count))
    norm = np.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / norm, x / norm, y / norm, z / norm
    rotation = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)                                                                   # (count, 3, 3)
    return np.matmul(base, rotation.transpose(0, 2, 1))                    # R @ d for every d


# ---- public estimators ------------------------------------------------------------------------------

def probe_sh(scene: Scene, points, directions: int = 1024, spp: int = 1, max_depth: int = -1,
             seed: int = 0, cache: bool = True) -> np.ndarray:
    """L2 SH (P, 9, 3) of the incident radiance L(p, w) at free-space points (P, 3).

    c_lm = integral L(p, w) Y_lm(w) dw, w pointing from p towards where the light comes from (the
    convention of `viewer.probes.sh`). Each probe traces `spp` independently rotated lattices of `directions`
    stratified directions, each ray with one light sample beside it. `max_depth` is Mitsuba's: path
    vertices after the probe (1: light seen directly, 2: one bounce, -1: unbounded with Russian
    roulette). The sun's delta lands as sun.irradiance * visibility * Y_lm(sun.direction).
    """
    p = np.asarray(points, np.float64).reshape(-1, 3)
    seed = int(seed) % 2**31
    params = dict(directions=int(directions), spp=int(spp), max_depth=int(max_depth), seed=seed)
    return _cached("probe_sh", scene, [p], params, cache,
                   lambda: _probe_sh(scene, p, int(directions), int(spp), int(max_depth), int(seed)))


def _probe_sh(scene, points, directions, spp, max_depth, seed, terms=None):
    terms = terms or _probe_terms
    mscene = load_scene(scene, max_depth)
    per_probe = directions * spp
    out = None
    for start, stop in _batches(len(points), per_probe):
        batch_seed = seed * 1_000_003 + start
        dirs = _lattice((stop - start) * spp, directions, batch_seed).reshape(stop - start, per_probe, 3)
        coefficients = _estimate(mscene, points[start:stop], dirs, terms, seed=batch_seed)
        if out is None:
            out = np.zeros((len(points), coefficients.shape[1]))
        out[start:stop] = coefficients
    parts = out.reshape(len(points), -1, sh.SH_COUNT, 3).astype(np.float32)
    return parts[:, 0] if parts.shape[1] == 1 else parts


def probe_sh_parts(scene: Scene, points, directions: int = 1024, spp: int = 1, max_depth: int = -1,
                   seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """`probe_sh` split into (reflected, emitted), each (P, 9, 3), from the same paths: the light
    reflected by surfaces (what the renderer's probes hold, since it shades emitters and the sun
    itself) and the light arriving straight from emitters and the sun. Their sum is `probe_sh`.
    Not cached (training scenes are seen once)."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    out = _probe_sh(scene, p, int(directions), int(spp), int(max_depth), int(seed) % 2**31, _probe_part_terms)
    return out[:, 0], out[:, 1]


def irradiance(scene: Scene, points, normals, spp: int = 1024, max_depth: int = -1, seed: int = 0,
               cache: bool = True, indirect_only: bool = False) -> np.ndarray:
    """Irradiance E(p, n) = integral L(p, w) max(0, n.w) dw (P, 3) at surface points (P, 3) with unit
    normals (P, 3), from `spp` cosine-distributed rays and light samples per point. The rays start a
    little off the surface along n (1e-5 of the scene size), so the surface itself is not hit.
    indirect_only: without the light arriving straight from emitters and the sun (what the renderer's
    probe grid holds)."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    seed = int(seed) % 2**31
    params = dict(spp=int(spp), max_depth=int(max_depth), seed=seed)
    kind = "irradiance"
    if indirect_only:
        params["indirect_only"], kind = True, "indirect-irradiance"
    return _cached(kind, scene, [p, n], params, cache,
                   lambda: _irradiance(scene, p, n, int(spp), int(max_depth), int(seed), indirect_only))


def _irradiance(scene, points, normals, spp, max_depth, seed, indirect_only=False):
    mscene = load_scene(scene, max_depth)
    lo, hi = scene.bounds
    offset = 1e-5 * max(float(np.linalg.norm(hi - lo)), 1e-6)
    out = np.zeros((len(points), 3))
    for start, stop in _batches(len(points), spp):
        batch_seed = seed * 1_000_003 + start
        n = normals[start:stop]
        dirs = _cosine_hemisphere(_lattice(stop - start, spp, batch_seed), n)       # (B, S, 3)
        terms = _indirect_irradiance_terms if indirect_only else _irradiance_terms
        out[start:stop] = _estimate(mscene, points[start:stop] + offset * n, dirs, terms, normals=n,
                                    seed=batch_seed)
    return out.astype(np.float32)


def _cosine_hemisphere(sphere: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Uniform sphere directions (B, S, 3) -> cosine-weighted directions about normals (B, 3).

    u = (1 - z)/2 is uniform on [0, 1) for a uniform sphere direction, and r = sqrt(u) with the same
    azimuth is Malley's cosine-weighted map; both keep measure, so the lattice stays stratified."""
    u = 0.5 * (1.0 - sphere[..., 2])
    phi = np.arctan2(sphere[..., 1], sphere[..., 0])
    r = np.sqrt(u)
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.clip(1.0 - u, 0.0, None))], axis=-1)
    t, b = _tangent_frame(normals)
    return (local[..., :1] * t[:, None] + local[..., 1:2] * b[:, None] + local[..., 2:] * normals[:, None])


def _tangent_frame(n: np.ndarray):
    """Orthonormal tangents of unit normals (Duff et al. 2017, "Building an orthonormal basis, revisited")."""
    sign = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=-1)
    s = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=-1)
    return t, s


def render(scene: Scene, camera: Camera | None = None, width: int = 256, height: int = 256,
           spp: int = 256, seed: int = 0, max_depth: int = -1, cache: bool = True) -> np.ndarray:
    """Path-traced (H, W, 3) float32 linear radiance seen from `camera` (default scene.camera; `fov` is
    vertical) through a box pixel filter, emitters visible."""
    camera = camera or scene.camera
    params = dict(camera=[*camera.origin, *camera.target, *camera.up, camera.fov], width=int(width),
                  height=int(height), spp=int(spp), seed=int(seed), max_depth=int(max_depth))
    return _cached("render", scene, [], params, cache,
                   lambda: _render(scene, camera, int(width), int(height), int(spp), int(seed),
                                   int(max_depth)))


def _render(scene, camera, width, height, spp, seed, max_depth):
    mi, _, _ = loaded()
    lo, hi = scene.bounds
    size = max(float(np.linalg.norm(hi - lo)), 1e-6)
    far = size + float(np.linalg.norm(np.asarray(camera.origin) - 0.5 * (lo + hi)))
    sensor = {
        "type": "perspective", "fov": float(camera.fov), "fov_axis": "y",
        "near_clip": 1e-4 * size, "far_clip": 10.0 * far,
        "to_world": mi.ScalarTransform4f().look_at(origin=list(camera.origin), target=list(camera.target),
                                                   up=list(camera.up)),
        "film": {"type": "hdrfilm", "width": width, "height": height, "pixel_format": "rgb",
                 "rfilter": {"type": "box"}},
        "sampler": {"type": "independent", "sample_count": spp},
    }
    image = mi.render(load_scene(scene, max_depth, sensor), spp=spp, seed=seed)
    return np.array(image, np.float32).reshape(height, width, 3)


def _cached(kind, scene, arrays, params, use_cache, compute):
    """Results are cached on disk (viewer.reference.cache), keyed by everything they depend on."""
    if not reference_cache.enabled(use_cache):
        return compute()
    mi, _, _ = loaded()
    tag = f"{CACHE_VERSION}|{kind}|{variant()}|{mi.__version__}"
    if scene.twins is not NO_TWIN:   # its sheets pulled apart since the cache's version: older results differ
        tag += "|sheets apart"
    return reference_cache.load_or_compute(kind, reference_cache.key(tag, scene, arrays, params), compute)
