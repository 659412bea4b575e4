"""Training targets for one scene: ground-truth probe SH and probe validity.

Three sources of truth: Mitsuba 3 (`viewer.reference.mitsuba.probe_sh_parts`, the independent path tracer;
unbiased, noisy at low direction counts), the physical solver (`viewer.physical.gi.PhysicalGI`: the geometry
traced once, the bounces solved to convergence; about a second a room, 4-5% off Mitsuba, and what the
issue-14 datasets use, docs/TRAINING.md says why) or the all-pairs numpy solver (the old `solver`). Both give the incident light at each probe and, apart, its part straight from
the emitters and the sun: the renderer shades that part itself, so its probes hold only the rest, the
light reflected by surfaces.

Validity follows the renderer's rule (`viewer.probes.grid.project`): a probe that sees the back of surfaces
in more than `ProbeSettings.invalid_backface_fraction` of its directions, marched through the 32^3
voxels, is inside a solid object.
"""

from __future__ import annotations

import numpy as np

from viewer.probes import sh
from viewer.physical.projection import ProbeSettings
from viewer.probes.grid import ProbeGrid, fill_invalid
from viewer.scene import Scene

TRUTHS = ("physical", "mitsuba", "solver")
VALIDITY_VOXELS = 32
"""Voxel resolution at which probe validity is decided."""
VALIDITY_DIRECTIONS = 128
"""Directions per probe for the back-face fraction (a fraction, so fewer than the renderer's 512 do)."""


def probe_validity(scene: Scene, lo, hi, resolutions, voxel_resolution: int = VALIDITY_VOXELS,
                   directions: int = VALIDITY_DIRECTIONS) -> dict[int, np.ndarray]:
    """{M: (M, M, M) bool}: False for probes inside solid geometry (the rule of `projection.project`)."""
    from viewer.rays.raymarch import BACKFACE, Tracer
    from viewer.rays.voxels import voxelize

    tracer = Tracer.build(voxelize(scene, voxel_resolution))
    dirs, _ = sh.sphere_directions(directions)
    limit = ProbeSettings().invalid_backface_fraction
    out = {}
    for m in resolutions:
        points = ProbeGrid.positions_for(lo, hi, m).reshape(-1, 3)
        hits = tracer.first_hits(np.repeat(points, len(dirs), axis=0), np.tile(dirs, (len(points), 1)))
        backface = (hits.reshape(len(points), len(dirs)) == BACKFACE).mean(axis=1)
        out[m] = (backface <= limit).reshape(m, m, m)
    return out


def mitsuba_available() -> bool:
    from viewer.reference import mitsuba as reference

    try:
        reference.variant()
    except reference.ReferenceUnavailable:
        return False
    return True


def mitsuba_sh(scene: Scene, lo, hi, resolution: int, directions: int, seed: int):
    """(total, direct), each (M, M, M, 9, 3) float32: the incident-radiance SH from Mitsuba at the probe
    centres, and its part straight from the emitters and the sun, from the same paths (not cached on
    disk: every scene is new)."""
    from viewer.reference import mitsuba as reference

    points = ProbeGrid.positions_for(lo, hi, resolution).reshape(-1, 3)
    reflected, direct = reference.probe_sh_parts(scene, points, directions=directions, seed=seed)
    shape = (resolution,) * 3 + (9, 3)
    return (reflected + direct).reshape(shape), direct.reshape(shape)


def unbiased_targets(scene: Scene, lo, hi, resolution: int, directions: int, seed: int) -> dict[str, np.ndarray]:
    """`sh_{M}_mitsuba` and `sh_{M}_mitsuba_direct`: Mitsuba's probes at few directions beside another
    truth's (the physical solver's): noisy but unbiased, so that training can average the noise out
    over the rooms where the solver's bias would stay (docs/TRAINING.md, "Targets")."""
    total, direct = mitsuba_sh(scene, lo, hi, resolution, directions,
                               int(np.random.default_rng([seed, resolution, 0x3C]).integers(2**31)))
    return {f"sh_{resolution}_mitsuba": np.asarray(total, np.float32),
            f"sh_{resolution}_mitsuba_direct": np.asarray(direct, np.float32)}


def solver_sh(scene: Scene, resolutions, directions: int, voxels: int) -> dict[int, tuple]:
    """{M: (total, direct, valid)} from the numpy solver over scene.bounds: the steps of
    `viewer.physical.gi.solve`, with the bounces solved once for every M. Its probes come filled already
    (`projection.project` calls `fill_invalid`), so raw and filled targets are the same array."""
    from viewer.physical import projection
    from viewer.physical import transport
    from viewer.physical.gi import GISettings
    from viewer.rays.raymarch import Tracer
    from viewer.rays.voxels import voxelize

    settings = GISettings(voxels=voxels, directions=directions)
    grid = voxelize(scene, settings.voxels, settings.normal_mode)
    tracer = Tracer.build(grid)
    transition = transport.transition_matrix(grid, settings.kernel, tracer)
    light = transport.solve(grid, scene.sun, transport.TransportSettings(settings.kernel, settings.bounces),
                            transition=transition, tracer=tracer)
    out = {}
    for m in resolutions:
        total, reflected = (projection.project(grid, light, scene.sun, scene.bounds, ProbeSettings(
            resolution=m, directions=directions, include_emitted=emitted), tracer) for emitted in (True, False))
        out[m] = (total.coefficients, total.coefficients - reflected.coefficients, total.valid)
    return out


def physical_sh(scene: Scene, resolutions, directions: int = 256, voxels: int = 32) -> dict[int, tuple]:
    """{M: (total, direct, valid, filled)} from the physical solver over scene.bounds (viewer.physical.gi's
    `PhysicalGI` stages): the voxels are traced and lit once, and each M traces only its probe rays
    (`geometry.with_probes`). total and direct are the probes as projected (raw), filled has the probes
    inside solids filled from valid neighbours (the renderer's `fill_invalid`)."""
    from viewer.physical import geometry as geometries
    from viewer.physical import lightpaths
    from viewer.physical import relight
    from viewer.physical.gi import GISettings, geometry_settings
    from viewer.rays.voxels import voxelize_with_faces

    resolutions = sorted(resolutions, reverse=True)
    settings = geometry_settings(GISettings(voxels=voxels, probes=resolutions[0], directions=directions))
    traced = geometries.trace(scene, voxelize_with_faces(scene, settings.voxels, settings.normal_mode), settings)
    lighting = None
    out = {}
    for m in resolutions:
        g = traced if m == resolutions[0] else geometries.with_probes(traced, m)
        lights = lightpaths.build(scene, g)
        sun = geometries.sun_paths(g, scene.sun)
        materials = relight.materials(scene, g, lights)
        lighting = relight.solve(g, lights, sun, materials, previous=lighting)
        total = relight.probe_coefficients(g, lights, sun, materials, lighting, True)
        reflected = relight.probe_coefficients(g, lights, sun, materials, lighting, False)
        filled = relight.probe_grid(g, total).coefficients
        shape = (m, m, m, 9, 3)
        out[m] = (total.reshape(shape), (total - reflected).reshape(shape), g.valid, filled)
    return out


def targets(scene: Scene, lo, hi, resolutions, truth: str, directions: int, seed: int,
            valid: dict[int, np.ndarray] | None = None, solver_voxels: int = 32) -> dict[str, np.ndarray]:
    """The arrays `sh_{M}`, `sh_{M}_filled`, `sh_{M}_direct` and `valid_{M}` for every M; `valid` (from
    `probe_validity`; Mitsuba only) may be computed elsewhere beforehand."""
    if truth not in TRUTHS:
        raise ValueError(f"truth must be one of {TRUTHS}, not {truth!r}")
    if truth == "physical":
        out = {}
        for m, (total, direct, valid_m, filled) in physical_sh(scene, resolutions, directions, solver_voxels).items():
            out.update({f"sh_{m}": np.asarray(total, np.float32), f"sh_{m}_direct": np.asarray(direct, np.float32),
                        f"valid_{m}": np.asarray(valid_m, bool), f"sh_{m}_filled": np.asarray(filled, np.float32)})
        return out
    if truth == "solver":
        solved = solver_sh(scene, resolutions, directions, solver_voxels)
    elif valid is None:
        valid = probe_validity(scene, lo, hi, resolutions)
    out = {}
    for m in resolutions:
        if truth == "solver":
            total, direct, valid_m = solved[m]
        else:
            valid_m = valid[m]
            total, direct = mitsuba_sh(scene, lo, hi, m, directions,
                                       int(np.random.default_rng([seed, m]).integers(2**31)))
        out[f"sh_{m}"] = np.asarray(total, np.float32)
        out[f"sh_{m}_direct"] = np.asarray(direct, np.float32)
        out[f"valid_{m}"] = np.asarray(valid_m, bool)
        filled = total if truth == "solver" else fill_invalid(total, valid_m)  # the solver's come filled
        out[f"sh_{m}_filled"] = np.asarray(filled, np.float32)
    return out
