"""One call from a Scene to its probe grid with the numpy solver: voxelize, light, bounce, project.

The settings here are the product defaults; `python -m viewer sample` and the viewer's "CPU solver" GI
source both come through `solve`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from viewer import probes, transport, voxels
from viewer.raymarch import Tracer
from viewer.scene import Scene


@dataclass(frozen=True)
class GISettings:
    voxels: int = 32
    """N: voxels per axis."""
    probes: int = 24
    """M: probes per axis over the scene bounds. Measured against Mitsuba (docs/ACCURACY.md): 16 gives
    about 6% relative RMSE on the Cornell boxes, 24 about 4%, within the product goal of 5%."""
    kernel: str = "physical"
    """Light transition kernel: `physical` or `paper` (see viewer.transport)."""
    bounces: int = 100
    """Most bounces summed (the solver stops earlier once converged)."""
    directions: int = 512
    """Directions gathered per probe for the reflected light. Against Mitsuba in free space 128, 256
    and 512 give 4.2%, 4.1% and 4.1% (Cornell box, 32^3 voxels, 24^3 probes), but on surfaces the
    renderer shows fewer directions as a cloudy texture (every probe samples the same lattice, so its
    error is structured, not noise): 512 keeps walls and ceiling smooth."""
    dering: float = 0.0
    """SH deringing strength (0 = off)."""
    invalid_backface_fraction: float = 0.25
    """Probes that see the back of surfaces in more than this fraction of directions are inside solid
    geometry: invalid, and filled from their valid neighbours (leak reduction, viewer.probes). 1 turns it
    off (every probe valid); docs/STABILITY.md measures both."""
    normal_mode: str = "area"
    """Voxel normals: `area` (area-weighted) or `paper` (eq. 3)."""


@dataclass
class Timings:
    """Seconds spent in each stage."""

    stages: dict[str, float] = field(default_factory=dict)

    def __str__(self):
        parts = [f"{name} {seconds:.3f}s" for name, seconds in self.stages.items()]
        return ", ".join(parts + [f"total {sum(self.stages.values()):.3f}s"])


def solve(scene: Scene, settings: GISettings = GISettings(), include_emitted: bool = True,
          timings: Timings | None = None) -> probes.ProbeGrid:
    return solve_parts(scene, settings, (include_emitted,), timings)[0]


def solve_parts(scene: Scene, settings: GISettings = GISettings(), parts: tuple[bool, ...] = (True, False),
                timings: Timings | None = None) -> list[probes.ProbeGrid]:
    """One transport solve projected once per entry of `parts`: with the emitted light (True, what
    `sample` returns) or without it (False, the indirect light the renderer shades from the probes)."""
    timings = timings if timings is not None else Timings()
    clock = time.perf_counter()

    def lap(name):
        nonlocal clock
        now = time.perf_counter()
        timings.stages[name] = timings.stages.get(name, 0.0) + now - clock
        clock = now

    grid = voxels.voxelize(scene, settings.voxels, settings.normal_mode)
    tracer = Tracer.build(grid)
    lap("voxelize")
    g = transport.transition_matrix(grid, settings.kernel, tracer)
    lap("transition")
    light = transport.solve(grid, scene.sun, transport.TransportSettings(settings.kernel, settings.bounces),
                            transition=g, tracer=tracer)
    lap("bounces")
    results = []
    for include_emitted in parts:
        probe_settings = probes.ProbeSettings(resolution=settings.probes, directions=settings.directions,
                                              include_emitted=include_emitted, dering=settings.dering,
                                              invalid_backface_fraction=settings.invalid_backface_fraction)
        results.append(probes.project(grid, light, scene.sun, scene.bounds, probe_settings, tracer))
    lap("probes")
    return results
