"""Baked probe grids: the converged light of one scene, written once for use outside the viewer.

`gi-viewer bake SCENE --out FILE.npz [--dds FILE.dds]` solves with the numpy transport solver
(viewer.physical.gi) and writes the result; `gi-viewer FILE.npz` opens it again: the scene it was baked from,
lit by the stored probes instead of a live solve. The keys of the .npz (version 1, docs/BAKED.md):

    format       str      "gi-viewer probe grid"
    version      int      1; a reader refuses a newer version
    lo, hi       (3,)     float64, the probe box in the scene file's units and axes (y up)
    resolution   int      M: the grid is M x M x M probes; probe (i, j, k) sits at
                          lo + ((i, j, k) + 0.5) * (hi - lo) / M
    sh_order     int      2: real orthonormal SH, bands 0..2, 9 coefficients per colour (viewer.probes.sh)
    sh_basis     str      the coefficient order and the direction convention, in words
    radiance     (M, M, M, 9, 3) float32 [x, y, z, coefficient, rgb]: incident radiance, all of it
                          (what `gi-viewer sample` returns at the probe centres)
    indirect     (M, M, M, 9, 3) float32: without the light arriving straight from emitters and the
                          sun (what a renderer that draws direct light itself shades from, as ours does)
    valid        (M, M, M) bool: False inside solid geometry (those probes hold values filled in from
                          valid neighbours)
    units        str      radiance in the units of the scene's emission, lengths in the file's units
    scene        str      the scene: a built-in name, or the file's absolute path when it was baked
    sun          (0,) or (6,) float64: dx, dy, dz (towards the sun), r, g, b irradiance
    settings     str      JSON of the viewer.physical.gi.GISettings it was solved with
    generator    str      "gi-viewer <version>"
"""

from __future__ import annotations

import dataclasses
import json
import struct
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from viewer.physical.work import MAX_PROBES, WorkError, check_probe_grid
from viewer.probes.grid import ProbeGrid
from viewer.scene.files import check_readable, inside as inside_folder
from viewer.scene.types import MAX_COORDINATE, DirectionalLight, SceneError
from viewer.output import replacing

FORMAT = "gi-viewer probe grid"
VERSION = 1
SH_BASIS = ("real orthonormal SH, (l, m) = 00, 1-1, 10, 11, 2-2, 2-1, 20, 21, 22; direction from the probe "
            "towards where the light comes from, world axes")
UNITS = "radiance: the scene's emitted-radiance units (linear RGB, per steradian); lengths: the scene file's units"
KEYS = ("format", "version", "lo", "hi", "resolution", "sh_order", "sh_basis", "radiance", "indirect", "valid",
        "units", "scene", "sun", "settings", "generator")
SLABS = 7
"""RGBA volumes that hold 27 coefficients and the validity (`texture_volumes`)."""


class BakedError(ValueError):
    """A file that is not a readable baked probe grid; the message is one line."""


@dataclass(frozen=True)
class BakedGrid:
    radiance: ProbeGrid
    """All the incident light (emitters and sun included)."""
    indirect: ProbeGrid
    """The light reflected by surfaces only: what the viewer's renderer shades from."""
    scene: str
    """The scene it was baked from: a built-in name or a file's absolute path."""
    sun: DirectionalLight | None = None
    settings: dict = dataclasses.field(default_factory=dict)


def bake(scene, source: str, settings, timings=None) -> BakedGrid:
    """Solve `scene` (loaded from `source`) with the numpy solver and keep both projections."""
    from viewer.physical import gi

    radiance, indirect = gi.solve_parts(scene, settings, (True, False), timings)
    path = Path(source)
    kept = str(path.resolve()) if path.suffix or path.exists() else str(source)
    return BakedGrid(radiance, indirect, kept, scene.sun, dataclasses.asdict(settings))


def write_npz(baked: BakedGrid, path: str | Path) -> None:
    from importlib.metadata import PackageNotFoundError, version

    try:
        generator = f"gi-viewer {version('gi-viewer')}"
    except PackageNotFoundError:  # running from a checkout that was never installed
        generator = "gi-viewer (source checkout)"
    grid, sun = baked.radiance, baked.sun
    with replacing(path) as out:  # a file object: np.savez would append .npz to another suffix
        np.savez_compressed(
            out, format=np.str_(FORMAT), version=np.int64(VERSION), lo=grid.lo, hi=grid.hi,
            resolution=np.int64(grid.resolution), sh_order=np.int64(2), sh_basis=np.str_(SH_BASIS),
            radiance=grid.coefficients, indirect=baked.indirect.coefficients, valid=grid.valid,
            units=np.str_(UNITS), scene=np.str_(baked.scene),
            sun=np.zeros(0) if sun is None else np.concatenate([sun.direction, sun.irradiance]),
            settings=np.str_(json.dumps(baked.settings)), generator=np.str_(generator))


MAX_TEXT_BYTES = 1 << 20
"""The largest text or small entry of a grid (its settings, scene name, box ...): 1 MiB."""


def member_limit(key: str) -> int:
    """The most bytes the entry `key` of a grid may hold once decompressed: the probes of a grid of
    MAX_PROBES per axis, as float64 at most; its validity; 1 MiB for the rest."""
    if key in ("radiance", "indirect"):
        return MAX_PROBES ** 3 * 27 * 8 + 4096
    if key == "valid":
        return MAX_PROBES ** 3 + 4096
    return MAX_TEXT_BYTES


def read_npz(path: str | Path) -> BakedGrid:
    """A baked grid, checked key by key; anything else is a BakedError naming the file.

    The size every entry declares (in the zip's directory and in its array header) is checked against
    `member_limit` before it is decompressed: a small file that unpacks to gigabytes is refused unread."""
    path = Path(path)
    try:
        check_readable(path, "baked probe grid")
    except SceneError as exc:
        raise BakedError(str(exc) if Path(path).exists() else f"{path}: no such file") from None
    try:
        with zipfile.ZipFile(path) as archive:
            members = {info.filename.removesuffix(".npy"): info for info in archive.infolist()}
            missing = [k for k in KEYS if k not in members]
            if missing:
                raise BakedError(f"{path}: not a baked probe grid (no {', '.join(missing[:3])})")
            values = {k: _member(path, archive, members[k], member_limit(k)) for k in KEYS}
    except BakedError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, struct.error, KeyError,
            NotImplementedError, MemoryError, RuntimeError) as exc:   # damaged bytes, whichever layer notices
        raise BakedError(f"{path}: not a readable .npz file ({type(exc).__name__})") from None
    try:
        with np.errstate(all="ignore"):   # overflow in a hostile box is refused below, not printed
            return _checked(path, values)
    except BakedError:
        raise
    except (TypeError, ValueError, RecursionError) as exc:  # a key of the wrong kind (an array where a number belongs)
        raise BakedError(f"{path}: malformed baked probe grid ({type(exc).__name__}: {exc})"[:300]) from None


def _member(path: Path, archive: zipfile.ZipFile, info: zipfile.ZipInfo, limit: int) -> np.ndarray:
    """One .npy entry of the archive, its declared sizes checked before its data is read."""
    key = info.filename.removesuffix(".npy")
    if info.file_size > limit:
        raise BakedError(f"{path}: entry {key!r} unpacks to {info.file_size / 2**20:.0f} MiB, more than the "
                         f"{limit / 2**20:.0f} MiB a baked grid's {key!r} may hold")
    with archive.open(info) as fh:
        version = np.lib.format.read_magic(fh)
        shape, _, dtype = (np.lib.format.read_array_header_1_0(fh) if version == (1, 0)
                           else np.lib.format.read_array_header_2_0(fh))
        if dtype.hasobject:
            raise BakedError(f"{path}: entry {key!r} holds Python objects, which a baked grid never does")
        count = int(np.prod(shape, dtype=object))
        if count * dtype.itemsize > limit:
            raise BakedError(f"{path}: entry {key!r} declares {count * dtype.itemsize / 2**20:.0f} MiB, more "
                             f"than the {limit / 2**20:.0f} MiB a baked grid's {key!r} may hold")
    with archive.open(info) as fh:
        return np.lib.format.read_array(fh, allow_pickle=False)


def is_baked_file(source) -> bool:
    """Whether a scene argument names a baked grid (`gi-viewer FILE.npz`) rather than a scene."""
    return Path(str(source)).suffix.lower() == ".npz"


def _checked(path: Path, v: dict) -> BakedGrid:
    def fail(what: str):
        raise BakedError(f"{path}: {what}")

    if str(v["format"]) != FORMAT:
        fail(f"format {str(v['format'])[:40]!r}, expected {FORMAT!r}")
    if v["version"].shape != () or not np.issubdtype(v["version"].dtype, np.integer):
        fail("version is not an integer")
    if int(v["version"]) > VERSION:
        fail(f"version {int(v['version'])} is newer than this gi-viewer reads ({VERSION})")
    m = int(v["resolution"]) if v["resolution"].shape == () and np.issubdtype(v["resolution"].dtype,
                                                                                np.integer) else -1
    if not 1 <= m <= MAX_PROBES:
        fail(f"resolution must be an integer 1..{MAX_PROBES}")
    try:
        check_probe_grid(m)   # the memory its probes take, against the limit every request has
    except WorkError as exc:
        fail(str(exc))
    for key in ("radiance", "indirect"):
        if v[key].shape != (m, m, m, 9, 3) or not np.issubdtype(v[key].dtype, np.floating):
            fail(f"{key} must be ({m}, {m}, {m}, 9, 3) floats, got {v[key].shape} {v[key].dtype}")
        if not np.all(np.isfinite(v[key])):
            fail(f"{key} holds NaN or infinity")
    if v["valid"].shape != (m, m, m) or v["valid"].dtype != bool:
        fail(f"valid must be ({m}, {m}, {m}) bool")
    lo, hi = v["lo"], v["hi"]
    if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        fail("lo and hi must be three finite numbers each")
    if max(np.abs(lo).max(), np.abs(hi).max()) > MAX_COORDINATE:
        fail(f"the probe box reaches beyond +-{MAX_COORDINATE:.0e}, as a scene's vertices may not")
    if not np.all(hi > lo):
        fail("the probe box is empty (hi must exceed lo on every axis)")
    if int(v["sh_order"]) != 2:
        fail(f"SH order {int(v['sh_order'])}: this gi-viewer reads order 2 (9 coefficients)")
    sun = None
    if v["sun"].size:
        if v["sun"].shape != (6,):
            fail("sun must be six numbers dx, dy, dz, r, g, b (or none)")
        try:
            sun = DirectionalLight(v["sun"][:3], v["sun"][3:])
        except ValueError as exc:
            fail(str(exc))
    try:
        settings = json.loads(str(v["settings"]))
    except (ValueError, RecursionError):   # not JSON, or nested past what the parser follows
        settings = None
    if not isinstance(settings, dict):
        fail("settings are not a JSON object")
    scene = str(v["scene"])
    if not scene:
        fail("no scene named")
    radiance = ProbeGrid(lo, hi, v["radiance"], v["valid"])
    return BakedGrid(radiance, radiance.with_coefficients(v["indirect"]), scene, sun, settings)


def scene_source(baked: BakedGrid, path: str | Path) -> str:
    """Where to load the baked scene from: a built-in name, or a file inside the baked file's own folder
    (the stored path, a relative one taken from that folder), else a file of the same name beside the
    baked file (the pair moved together). A grid never opens a scene outside its folder: a file that names
    one is refused, as is a scene file that is not a regular file (a pipe would block)."""
    from viewer.scene import builtin_names

    stored = Path(baked.scene)
    if not stored.suffix:
        if baked.scene in builtin_names():
            return baked.scene
        raise BakedError(f"{path}: its scene {baked.scene!r} is not a built-in scene")
    folder = Path(path).resolve().parent
    try:
        named = (folder / stored).resolve()
    except (OSError, ValueError, RuntimeError):
        named = None
    inside = named is not None and named.is_relative_to(folder)
    beside = inside_folder(folder, stored.name)   # a link beside the grid that points elsewhere is not beside it
    for candidate in ([named] if inside else []) + ([beside] if beside is not None else []):
        if candidate.exists():
            try:
                check_readable(candidate)
            except SceneError as exc:
                raise BakedError(f"{path}: its scene {exc}") from None
            return str(candidate)
    if beside is None and (folder / stored.name).exists():
        raise BakedError(f"{path}: its scene {stored.name} beside it links to {(folder / stored.name).resolve()}, "
                         f"outside the baked file's folder {folder} (a grid opens only a scene beside it or below it)")
    if not inside and named is not None and named.exists():
        raise BakedError(f"{path}: its scene {baked.scene} lies outside the baked file's folder {folder} (a grid "
                         f"opens only a scene beside it or below it: move the grid next to its scene)")
    raise BakedError(f"{path}: its scene {baked.scene} is gone (and no {stored.name} beside the baked file)")


def load_scene(baked: BakedGrid, path: str | Path):
    """The scene the grid was baked from, with the sun it was baked with."""
    from viewer.scene import load

    return load(scene_source(baked, path), sun=baked.sun)


def texture_volumes(grid: ProbeGrid) -> np.ndarray:
    """(7 M, M, M, 4) float32 texels, [z, y, x] within each of 7 slabs stacked along z: slab t holds
    the 27 coefficients' numbers 4t .. 4t + 3 in coefficient-major RGB order (c0.r c0.g c0.b c1.r | c1.g
    c1.b c2.r c2.g | ...) and the last slab's alpha holds the validity (1 or 0). Not premultiplied:
    invalid probes hold values filled in from valid neighbours, so plain trilinear sampling works; a
    sampler clamps z to [0.5, M - 0.5] texels within a slab so that slabs do not bleed into each other."""
    m = grid.resolution
    flat = grid.coefficients.transpose(2, 1, 0, 3, 4).reshape(m, m, m, 27)
    flat = np.concatenate([flat, grid.valid.transpose(2, 1, 0)[..., None].astype(np.float32)], axis=-1)
    return np.concatenate([flat[..., 4 * t:4 * t + 4] for t in range(SLABS)], axis=0).astype(np.float32)
