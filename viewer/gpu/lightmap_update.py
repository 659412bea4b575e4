"""One update of the indirect lightmap, pass by pass (viewer/gpu/indirect_bake.py `update`): what the
pixels the final gather's rays land on reflect (`Landing`, `reflectance`, `gather_reflected`), and the
samples' light spread onto the texels that the gather's light reaches (`Reached`, `gather_texels`). The
parts are made once per geometry and lattice; the compiled passes run on every GI update.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from viewer.gpu.direct_bake import BakedDirectLight
from viewer.scene.textures import relative_at


@dataclass(frozen=True)
class Reached:
    """The samples and texels that the final gather's light reaches: a sample whose filter averages no
    record with a ray that landed gets 0 on every update, and so does a texel that reads only such
    samples (the backs of a room's walls: 38% of the Cornell box's samples). An update filters and spreads
    the others alone; the texels left out keep the 0 they were given once."""

    samples: np.ndarray
    """The samples the filter is evaluated at (rows of `tent_neighbours`' near and tent): those the
    texels below read with a weight."""
    texels: np.ndarray
    """The texels (rows of the texels' pixels, rows and weights) that read a sample some light reaches."""

    @staticmethod
    def of(landed: np.ndarray, near: np.ndarray, tent: np.ndarray, rows: np.ndarray, weights: np.ndarray,
           dark: tuple[np.ndarray, np.ndarray] | None = None) -> "Reached":
        """landed: the records with a ray that landed (`GatherRays.landed`); (near, tent) (S, K): each
        sample's records and weights; rows and weights (N, 4): the samples every texel interpolates;
        dark (rows, lit rows): samples that show another's light (the update copies it: `with_lit`)."""
        dark, lit = dark if dark is not None else (np.zeros(0, np.int64), np.zeros(0, np.int64))
        samples, texels = _reached(np.asarray(landed, np.int64), near, tent, rows, weights, dark, lit)
        return Reached(with_lit(samples, dark, lit), texels)


def with_lit(samples: np.ndarray, dark: np.ndarray, lit: np.ndarray) -> np.ndarray:
    """The rows `samples` (ascending) and the lit rows whose light the dark ones among them show."""
    if len(dark) == 0:
        return samples
    return _with_lit(samples, dark, lit, max(samples.max() if len(samples) else 0, lit.max()) + 1)


@numba.njit(cache=True, nogil=True)
def _with_lit(samples, dark, lit, size):
    read = np.zeros(size, np.bool_)
    for s in samples:
        read[s] = True
    for i in range(dark.shape[0]):
        if read[dark[i]]:
            read[lit[i]] = True
    return np.flatnonzero(read)


@numba.njit(cache=True, nogil=True, parallel=True)
def _reached(landed, near, tent, rows, weights, dark, lit):
    """(samples, texels) of `Reached.of`: in compiled passes over the samples and texels (numpy's took 150 ms
    of the Cornell box's first update after new geometry)."""
    has_landed = np.zeros(max(near.max(), landed.max() if landed.size else -1) + 1, np.bool_)
    for r in landed:
        has_landed[r] = True
    reached = _reads(near, tent, has_landed)                # the samples some landed ray's light reaches
    for i in range(dark.shape[0]):
        reached[dark[i]] = reached[lit[i]]
    texels = np.flatnonzero(_reads(rows, weights, reached))
    return _weighted_rows(rows, weights, texels, near.shape[0]), texels


@numba.njit(cache=True, nogil=True)
def _weighted_rows(rows, weights, which, size):
    """The distinct rows[i, k] (< size) with weights[i, k] > 0 over the i of `which`, ascending."""
    read = np.zeros(size, np.bool_)
    for i in which:
        for k in range(rows.shape[1]):
            if weights[i, k] > 0:
                read[rows[i, k]] = True
    return np.flatnonzero(read)


@numba.njit(cache=True, nogil=True, parallel=True)
def _reads(index, weights, flags):
    """(N,) bool: the rows i with some k where weights[i, k] > 0 and flags[index[i, k]]."""
    out = np.zeros(index.shape[0], np.bool_)
    for i in numba.prange(index.shape[0]):
        for k in range(index.shape[1]):
            if weights[i, k] > 0 and flags[index[i, k]]:
                out[i] = True
                break
    return out


@numba.njit(cache=True, nogil=True, parallel=True)
def gather_texels(values, rows, weights, pixels, image, which):
    """image[pixels[t]] = sum_k weights[t, k] values[rows[t, k]] for each t of `which`: each texel shows its
    samples' light (and the filter gives each sample its records')."""
    for i in numba.prange(which.shape[0]):
        t = which[i]
        r, g, b = _texel(values, rows, weights, t)
        p = pixels[t]
        image[p, 0], image[p, 1], image[p, 2] = r, g, b


@numba.njit(cache=True, nogil=True, parallel=True)
def gather_reflected(values, rows, weights, albedo, reflected, out):
    """out[i] = albedo[i] x (sum_k weights[i, k] values[rows[i, k]]) + reflected[i]: what each pixel that
    the gather's rays land on reflects (`Landing`), its samples' light taken as `gather_texels` takes it."""
    for i in numba.prange(rows.shape[0]):
        r, g, b = _texel(values, rows, weights, i)
        out[i, 0] = albedo[i, 0] * r + reflected[i, 0]
        out[i, 1] = albedo[i, 1] * g + reflected[i, 1]
        out[i, 2] = albedo[i, 2] * b + reflected[i, 2]


@dataclass(frozen=True)
class Landing:
    """The pixels of the (front | back) image that the final gather's rays land on (`GatherRays.landing`),
    and what an update reads for each: the samples it interpolates, its face and its texel. Made once per
    geometry and lattice (the rows follow the probes' weights: `BakedIndirectLight._sources`)."""

    pixels: np.ndarray
    """(L,) int64, in image order."""
    rows: np.ndarray
    """(L, 4) the rows of the update's sample values each pixel interpolates ..."""
    weights: np.ndarray
    """... (L, 4) float32 with these weights (0 for a pixel that is no covered texel: it reflects nothing)."""
    faces: np.ndarray
    """(L,) each pixel's face among the scene's non-degenerate ones, -1 for none."""
    texels: np.ndarray
    """(L,) each pixel's texel (a row of lightmap.texel_points), -1 for none."""
    samples: np.ndarray
    """The rows of the update's sample values that `rows` reads (with a weight): the probes' light is
    needed there alone (on the Cornell box 54k of the 140k samples, both sides), the final gather's
    filter writes every sample afterwards."""

    @staticmethod
    def of(pixels: np.ndarray, texel_pixels: np.ndarray, texel_rows: tuple[np.ndarray, np.ndarray],
           texel_faces: np.ndarray, size: int) -> "Landing":
        """texel_pixels (2T,) and texel_rows ((2T, 4), (2T, 4)): the pixel of every covered texel, front
        sides then back, and the samples its light is spread from and how; texel_faces (T,): each texel's
        face among the scene's non-degenerate ones; `size`: the image's pixels."""
        rows, weights = texel_rows
        return Landing(pixels, *_landing_reads(pixels, np.ascontiguousarray(texel_pixels), rows, weights,
                                               np.ascontiguousarray(texel_faces), size))


@numba.njit(cache=True, nogil=True, parallel=True)
def _landing_reads(pixels, texel_pixels, texel_rows, texel_weights, texel_faces, size):
    """(rows, weights, faces, texels, samples) of `Landing.of`, in compiled passes (numpy's took 60 ms of
    the Cornell box's first update after new geometry)."""
    spread = np.full(size, -1, np.int32)
    for i in numba.prange(texel_pixels.shape[0]):
        spread[texel_pixels[i]] = i
    count, half = pixels.shape[0], max(texel_pixels.shape[0] // 2, 1)
    rows = np.zeros((count, texel_rows.shape[1]), texel_rows.dtype)
    weights = np.zeros((count, texel_rows.shape[1]), np.float32)
    faces, texels = np.full(count, -1, np.int64), np.full(count, -1, np.int64)
    for i in numba.prange(count):
        t = spread[pixels[i]]
        if t >= 0:
            rows[i], weights[i] = texel_rows[t], texel_weights[t]
            faces[i], texels[i] = texel_faces[t % half], t % half
    samples = _weighted_rows(rows, weights, np.arange(count), texel_rows.max() + 1 if texel_rows.size else 0)
    return rows, weights, faces, texels, samples


@numba.njit(cache=True, nogil=True, inline="always")
def _texel(values, rows, weights, i):
    r = g = b = np.float32(0.0)
    for k in range(rows.shape[1]):
        w = weights[i, k]
        if w != 0.0:
            q = rows[i, k]
            r += w * values[q, 0]
            g += w * values[q, 1]
            b += w * values[q, 2]
    return r, g, b


@numba.njit(cache=True, nogil=True, parallel=True)
def reflectance(pixels, faces, face_albedo, ratio, direct, scale, albedo, reflected):
    """albedo[i] = face_albedo[faces[i]] (times ratio[i], the texture where a scene has one, at most 0.999)
    and reflected[i] = albedo[i] x direct[pixels[i]] x scale (a lamp's new colour since the bake): what
    each pixel that the gather's rays land on reflects (0 off the covered texels: faces[i] = -1), once per
    colour edit or bake, in one pass."""
    textured = ratio.shape[0] > 0
    for i in numba.prange(pixels.shape[0]):
        p, f = pixels[i], faces[i]
        for c in range(3):
            a = np.float32(0.0)
            if f >= 0:
                a = face_albedo[f, c]
                if textured:
                    a = min(a * ratio[i, c], np.float32(0.999))
            albedo[i, c] = a
            reflected[i, c] = a * (direct[p, c] * scale[c])


def texture_ratio(scene, lightmap: BakedDirectLight, faces: np.ndarray, texels: np.ndarray) -> np.ndarray | None:
    """(N, 3) float32 texture(uv) / its mean at texels (rows of lightmap.texel_points; -1 for none: 1)
    whose faces among the non-degenerate ones are `faces` (1 on plain faces): what a pixel's albedo is
    its face's times. None for a scene without textures."""
    if not scene.textured:
        return None
    kept = np.flatnonzero(scene.face_areas > 0)
    on = texels >= 0
    out = np.ones((len(texels), 3), np.float32)
    out[on] = relative_at(scene, kept[faces[on]], lightmap.texel_points[texels[on]])
    return out
