"""The benchmark's table of methods, name -> Method, in report order: the solvers, the edits, Mitsuba, and
what providers add (the shipped and swept networks, the paper's families). `python -m viewer bench` runs
what it selects from `registry()`; the methods themselves are viewer.bench.methods and
viewer.bench.edit_methods.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable, Iterable

from viewer import sources
from viewer.bench.edit_methods import edit_method, screen_edit_method
from viewer.bench.methods import (DEFAULT, Method, ambient_method, compute_method, mitsuba_points_method,
                                  mitsuba_probes_method, neural_methods, solver_grid, solver_method)
from viewer.physical.gi import GISettings

PROVIDERS: list[Callable[[bool], Iterable[Method]]] = [neural_methods]
"""Functions quick -> methods, asked each time the registry is built: the shipped and swept ProbeNets,
and what others register, such as the paper's families (Table 1) where `python -m viewer.training.table1`
has exported them (viewer/bench/run.py registers `paper_families.paper_family_methods`: that module builds
on this one)."""


def register_provider(provider: Callable[[bool], Iterable[Method]]) -> None:
    if provider not in PROVIDERS:
        PROVIDERS.append(provider)


def registry(quick: bool = False) -> dict[str, Method]:
    """Every method, in report order. Quick: a handful that together take well under a minute."""
    if quick:
        small = GISettings(voxels=16, probes=8)
        methods = [ambient_method(), *(mitsuba_points_method(d) for d in (16, 64, 256)),
                   solver_method(GISettings(voxels=8, probes=8)), compute_method(small),
                   edit_method(small, "colour", "compute"), mitsuba_probes_method(8, 64)]
    else:
        # The numpy solver at 64^3 voxels would hold a 27730^2 transition matrix (6 GB) and take hours:
        # 64^3 runs on the compute solver only. At 32^3 its bounces cost little beside the transition
        # matrix and the probe projection, so its bounce sweep would repeat one time four times.
        methods = [ambient_method()]
        methods += [compute_method(s) for s in solver_grid()]
        methods += [compute_method(replace(DEFAULT, kernel="paper"))]
        methods += [solver_method(replace(DEFAULT, voxels=16)), solver_method(DEFAULT),
                    solver_method(replace(DEFAULT, voxels=16, kernel="paper"))]
        methods += [edit_method(DEFAULT, kind, backend) for backend in (sources.COMPUTE.name, sources.SOLVER.name)
                    for kind in ("colour", "lamp")]
        methods += [screen_edit_method(source, kind) for source in (sources.COMPUTE.name, sources.NEURAL.name)
                    for kind in ("colour", "lamp")]
        methods += [mitsuba_points_method(d) for d in (16, 64, 256, 1024)]
        methods += [mitsuba_probes_method(m, d) for m, d in ((8, 64), (16, 64), (16, 256), (24, 256), (32, 256))]
    for provider in PROVIDERS:
        methods += list(provider(quick))
    return {m.name: m for m in methods}
