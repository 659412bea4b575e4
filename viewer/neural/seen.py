"""The seen feature: the light the surfaces reflect once, gathered at each probe by a few exact rays.

The one-bounce feature (viewer/neural/bounce.py) gathers that light with no visibility: every lit patch
shines on every probe, through walls. Gathered that way, even the solver's exact converged surface light
is 45% off the reflected light at the probes (docs/TRAINING.md, the visibility ladder), and a network
cannot recover what the gather threw away: which surfaces a probe sees. A few rays a probe, cast once
per geometry on the scene's own triangles, carry it: on the ladder, 16 rays a probe and a plain 3x3x3
filter took the same light from 45% to 30%, where 16 voxel cones reached 42%. So the network gets the
noisy ray gather beside the smooth unshadowed one and learns to denoise the first with the second.

Each ray lands on the voxel whose surface it meets (viewer.rays.voxel_rays: the same lookup as the
solver's probe rays; a back face or nothing brings no light) and takes that voxel's once-reflected
light: albedo x its direct irradiance / pi (`Bounce.leaving`). The directions are interleaved over the
lattice (`interleaved_lattices`): the 27 probes of any 3x3x3 block take the 27 disjoint subsets of one
spherical Fibonacci lattice of 27 x SEEN_RAYS directions, so the neighbourhood that the network's
filter averages holds 27 x SEEN_RAYS evenly spread directions (1,728 at 64 rays a probe). Measured at
16 rays a probe, where 27 independently turned lattices overlapped and left gaps: the same rays and
cost, and less error once filtered (on the solver's converged light, 3x3x3 box filtered against its
probes, 8.0% instead of 8.9% on the paper's seven scenes and 29.4% instead of 31.1% in 20 validation
rooms, median; 32 turned rays a probe give 7.7% and 28.0%).

The light bounces on, and the seen feature follows it one bounce further (`seen_light`): what the rays
gathered is read back at the voxels (`bounce.READ_BACK` voxels in front of each) and reflected again,
and gathered again. On 20 validation rooms, against the solver's reflected light (best gain a room,
3x3x3 box filtered, median): the unshadowed bounce 46.6%, the seen bounce 33.0%, seen twice 29.5%
(a third bounce 29.3%), where the solver's converged surface light gathered by the same 16 rays is
30.0%. So two bounces carry all that these rays can of the light's shape; its amount needs more where the
walls reflect much (SEEN_BOUNCES).

Kept per geometry (`SeenRays`): the rays are cast once; a light or colour edit gathers the voxels' new
light again, each gather a (P, 9, R) x (P, R, 3) product (the bounces that only feed the next one on a
quarter of the rays: CHAIN_EVERY). A moved object or lamp casts again only the rays
that pass through the box around its old and new places; the others keep the face they met and are
landed again on the new voxels.
"""

from __future__ import annotations

from functools import lru_cache

import numba
import numpy as np

from viewer.neural.changes import same_voxels
from viewer.neural.seen_links import lattice_links, open_box
from viewer.probes import sh
from viewer.rays.packets import LANES
from viewer.rays.voxel_rays import VoxelRays
from viewer.rays.voxels import VoxelGrid

SEEN_RAYS = 64
"""Rays a probe: the fewest that keep the network's reflected light within 1.5x the solver's error in
every scene of `python -m viewer.training.evaluate --val 20 --dark 4`. Scenes above 1.5x, and the
worst: the network trained on 32 rays 3 of 26 (val-00012 1.70x); fine-tuned from it on the same 1,605
rooms' features at 48 rays (6 epochs of 500 steps) 3 (1.52x), at 64 rays none (1.49x), at 128 rays none
(1.35x). With fewer rays the network's seen filter learns to blur more (its DC kernel's
centre 14% of the kernel at 32 rays, 30% at 128) and the light it blurs across is the error left. The
shipped network, fine-tuned 8 epochs more, is 1.48x at worst; the 48-ray one, fine-tuned the same 8
epochs more, stays above in two (val-00007 and val-00016, 1.51x). 64 rays cost a new generator room 36-39
ms more (val-00002 and val-00004: 99-115 -> 138-151 ms), a moved object 6-9 ms (the rays through its
box), an albedo edit the gathers' 1-3 ms; docs/PERFORMANCE.md has the shares of the solver's time."""
SEEN_BOUNCES = 4
"""Bounces the seen feature gathers; the last one also carries the bounces after it (`seen_light`). With
three, the tail fell short where the walls reflect much: on the Cornell box the seen light's red was 7%
under the solver's probes (4.4% with ten bounces, 4.6% with four), and the network, which adds to its
seen light, gave 6% too little red indirect light and 3% too little green and blue. Four bounces cost a
new Cornell box, a moved box or an albedo edit 1-3 ms."""
TAIL_RATIO_MAX = 0.95
"""The most of its light a room's surfaces are taken to reflect from one bounce to the next (the
geometric tail's ratio): past it the tail's 1 / (1 - r) would grow without bound."""
SEED = 0x5EE
"""The directions' rotation: the same in training and in the viewer."""
CHAIN_EVERY = 4
"""The bounces after the first that only feed the next one gather one in CHAIN_EVERY of each probe's
rays (`SeenRays.gathered`'s `part`: every CHAIN_EVERY-th along its spiral, which its directions list
first); the first bounce and the last gather, of every later bounce's light together, take them all.
The filter after each gather averages 27 probes' rays: the network's reflected light moved by at most
0.01x the solver's error in every evaluation scene (every bounce on a quarter of the rays took val-00012
from 1.497x to 1.520x), and a gather of a quarter takes 0.55-0.62 ms where all take 1.03-1.10 (24^3
probes, two cores): an albedo edit 0.1-0.9 ms sooner."""


class SeenRays:
    """`rays` directions from each of `points` (P, 3), cast once on `landing` (the encoder's voxels'
    listing of the scene's triangles): the voxel each one lands on, and the SH weights that gather the
    light it brings."""

    def __init__(self, landing: VoxelRays, count: int, points: np.ndarray, rays: int = SEEN_RAYS,
                 seed: int = SEED, previous: "SeenRays | None" = None, box=None, voxels: VoxelGrid | None = None,
                 reuse: bool = False):
        """`previous`, `box`: the same probes' rays in the scene before some triangles moved, and the
        box around those triangles' old and new places (`lattice.moved_box`): the rays that do not pass
        through it meet the same face at the same distance, and are only landed again on the new
        voxels' listing (a ray that passes beside the box lands on the voxels there as they are now):
        a small box moved in the Cornell box traces 26k of its 221k rays again (64k with the box widened
        by three cells, which the rays beside it do not need). `voxels`: the voxels `landing` lists; given
        here and to `previous`, a kept ray takes the new index of the voxel it landed on before where that
        voxel kept its surface (`changes.same_voxels`), without looking it up (the Cornell box's moved box:
        these rays 16.6 -> 12.4 ms). `reuse`: `previous` is dropped after this, and its rays' arrays are
        updated in place to become these (it cannot serve again): the kept rays' faces and distances are then
        neither copied nor read (val-00001's moved box, the encoder's reuse against copies by turns: its
        seen rays 11.4 -> 10.6 ms, its whole update 71.5 -> 70.0 ms, on a slow moment of the machine)."""
        self.count, self.rays, self.probes, self.points, self.seed = int(count), int(rays), len(points), points, seed
        directions, self._basis, self._sets = lattice_rays(len(points), self.rays, seed)
        before = None
        if (box is not None and previous is not None and previous._faces is not None
                and (previous.rays, previous.seed) == (self.rays, seed)
                and (previous.points is points or np.array_equal(previous.points, points))):
            before = previous._faces[:2]
            if voxels is not None and previous._voxels is not None:
                match = same_voxels(previous._voxels, voxels)
                remap = np.full(previous._voxels.count, -1, np.int32)
                remap[match[match >= 0]] = np.flatnonzero(match >= 0)
                before = (*before, previous._faces[2], remap)
        if before is None:
            landed = landing.kept_bundle(points, directions, None, None, lattice_packets(len(points), self.rays, seed),
                                         none=self.count)
        else:   # the directions a subset of probes shares, read without a copy a probe
            distinct, sets = lattice_directions(len(points), self.rays, seed)
            reuse = reuse and len(before) == 4
            landed = landing.kept_bundle(points, distinct, before, box, None, sets, none=self.count, in_place=reuse)
            if reuse:   # its arrays are these rays' now
                previous._faces = previous.voxel = None
        self.traced = landed.traced
        """How many of the rays were traced (the others landed again)."""
        self._faces = None if landed.faces is None else (landed.faces, landed.t, landed.hits)
        """(P, R) the face each ray met, its distance and the voxel it landed on, for the rays after a move."""
        self._voxels = voxels
        self.open = (1.0 - landed.backs / self.rays).astype(np.float32)
        """(P,) the share of each probe's rays that leave it through the front of a surface or into the
        open: near 0 inside a solid, whose rays meet the backs of its faces."""
        self.voxel = landed.sources.reshape(-1)
        """(P x R,) the voxel each ray lands on; `count` where it brings no light."""
        self.links = lattice_links(landing, points, None if before is None else (previous.links, box))
        """(3, m, m, m) bool on a cubic lattice (else None): whether the segment from each probe to its
        next one along x, y, z crosses no surface (`filtered` does not average across a wall)."""

    @property
    def distances(self) -> np.ndarray | None:
        """(P, R) how far each ray went to the face it met (None where the caster gives no faces)."""
        return None if self._faces is None else self._faces[1]

    def filtered(self, light: np.ndarray) -> np.ndarray:
        """(P, 9, C) `light` averaged over the 3x3x3 probes around each, each probe weighted by its open
        share, and a neighbour beyond the lattice's faces or across a surface (`links`) taken as the
        probe itself: the network's seen filter at its start (the box), that stops at walls. `light` as
        it is where the probes are not a cubic lattice."""
        if self.links is None:
            return light
        side = self.links.shape[1]
        light = np.ascontiguousarray(light, np.float32)
        shape = light.shape
        out = open_box(light.reshape(side, side, side, -1), self.open.reshape(side, side, side), self.links)
        return out.reshape(shape)

    def gathered(self, radiance: np.ndarray, part: bool = False) -> np.ndarray:
        """(P, 9, C) the light of the voxels leaving with `radiance` (K, C), as the rays see it (one
        compiled pass over the rays: half the time of a fancy-indexed copy and a batched product).
        `part`: each probe's first rays alone (one in CHAIN_EVERY, `part_basis`)."""
        radiance = np.asarray(radiance, np.float32)
        channels = radiance.shape[1]
        padded = np.zeros((len(radiance) + 1, -(-channels // 3) * 3), np.float32)   # a row for no light
        padded[:-1, :channels] = radiance
        voxel = self.voxel.reshape(self.probes, self.rays)
        basis = part_basis(self.probes, self.rays, self.seed) if part else self._basis
        parts = [_gathered(voxel, self._sets, basis, np.ascontiguousarray(padded[:, c:c + 3]))
                 for c in range(0, padded.shape[1], 3)]
        return (parts[0] if len(parts) == 1 else np.concatenate(parts, axis=2))[:, :, :channels]


def seen_light(rays: SeenRays, bounce, albedo: np.ndarray, leaving: np.ndarray,
               bounces: int = SEEN_BOUNCES) -> tuple[np.ndarray, np.ndarray]:
    """(P, 9, C) the light the voxels reflect, as `rays` see it: once to `bounces` times, and the bounces
    after those as a geometric tail; and (K, C) that light on the voxels (every bounce's radiance
    leaving them, the tail's included), which the unshadowed gather takes (the `bounce` input).
    `leaving` (K, C) is their once-reflected radiance (`Bounce.leaving`), and each further bounce
    reflects what the rays gathered (`Bounce.reflected`, for the voxels' `albedo` (K, C)), read through
    the open-weighted 3x3x3 filter (`SeenRays.filtered`): a voxel lit by the few rays of one probe carries
    their noise into every later bounce, and filtered it is lit as the network's start sees it (the
    public scenes' seen light, box filtered, 12.0% -> 10.6% off Mitsuba's indirect light).

    The tail: from one bounce to the next the voxels reflect a share r of the light (per colour, their
    area-weighted sums of the last two bounces' radiance, at most TAIL_RATIO_MAX); the bounces after the
    last one gathered add r + r^2 + ... of it, so the last one counts 1 / (1 - r) times. In a room of
    near-white walls (r about 0.7-0.8) two bounces gather less than half of the reflected light and the
    network had to guess the rest from the albedo it sees (it gave 0.43x the truth); with the tail the
    seen light is 22% off the solver's in such rooms where two bounces were 45% off (3 rooms, best gain:
    1.67 for two bounces, 0.97 with the tail), and in 20 validation rooms 29.3% where two bounces were
    29.5% (best gain 0.99 against 1.12).

    The first bounce is gathered on every ray, the later ones on one in CHAIN_EVERY, and the seen light is
    the first bounce's gather plus one gather of every later bounce's light together."""
    leaving = np.asarray(leaving, np.float32)
    once = rays.gathered(leaving)
    later = np.zeros_like(leaving)
    before = leaving
    for step in range(1, bounces):
        gathered = once if step == 1 else rays.gathered(before, part=True)
        reflected = bounce.reflected(albedo, rays.filtered(gathered))
        if step == bounces - 1:
            reflected = reflected / (1.0 - tail_ratio(bounce.area, reflected, before)).astype(np.float32)
        later += reflected
        before = reflected
    return once + rays.gathered(later), leaving + later


def tail_ratio(area: np.ndarray, light: np.ndarray, before: np.ndarray) -> np.ndarray:
    """(C,) the share of `before` (K, C), a bounce's radiance leaving the voxels of `area` (K,), that the
    next bounce's `light` is, area-weighted, in [0, TAIL_RATIO_MAX]."""
    area = np.asarray(area, np.float64)[:, None]
    ratio = (area * light).sum(axis=0) / np.maximum((area * before).sum(axis=0), 1e-30)
    return np.clip(ratio, 0.0, TAIL_RATIO_MAX)


@lru_cache(maxsize=2)
def lattice_rays(count: int, rays: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rays of `count` probes, whatever the scene: their directions (count, rays, 3)
    (`interleaved_lattices` on a cubic lattice of `count` probes, else `turned_lattices`), and the SH
    weights that gather what they bring as S distinct sets (S, 9, rays) float32 with the set of each
    probe (count,) int32: each direction's basis times the Monte Carlo weight of a uniform direction on
    the sphere, 4 pi / rays. An interleaved lattice has INTERLEAVE^3 sets, 16 KB that stay in the
    cache while a gather reads them for every probe (a turned lattice has one a probe). Made once per
    lattice (read-only): 20 ms of a new Cornell box's 120."""
    distinct, sets = lattice_directions(count, rays, seed)
    directions = distinct[sets]
    basis = np.ascontiguousarray((sh.basis(distinct) * (4.0 * np.pi / rays)).transpose(0, 2, 1), np.float32)
    for array in (directions, basis):
        array.flags.writeable = False
    return directions, basis, sets


@lru_cache(maxsize=2)
def part_basis(count: int, rays: int, seed: int) -> np.ndarray:
    """(S, 9, rays / CHAIN_EVERY) `lattice_rays`' SH weights of each set's first rays (one in CHAIN_EVERY
    along the set's spiral: `chain_first`), each weighted as the share of the sphere that so many rays
    take."""
    _, basis, _ = lattice_rays(count, rays, seed)
    part = max(rays // CHAIN_EVERY, 1)
    out = np.ascontiguousarray(basis[:, :, :part] * np.float32(rays / part), np.float32)
    out.flags.writeable = False
    return out


@lru_cache(maxsize=2)
def lattice_directions(count: int, rays: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """`lattice_rays`' directions as S distinct sets (S, rays, 3) and the set of each probe (count,)
    int32 (read-only), which the ray casts read instead of a copy a probe (10.6 MB for 24^3 probes)."""
    side = round(count ** (1.0 / 3.0))
    if side ** 3 == count:
        distinct, sets = interleaved_subsets(rays, seed), interleaved_sets(side)
    else:
        distinct, sets = turned_lattices(count, rays, seed), np.arange(count, dtype=np.int32)
    for array in (distinct, sets):
        array.flags.writeable = False
    return distinct, sets


@lru_cache(maxsize=2)
def lattice_packets(count: int, rays: int, seed: int) -> np.ndarray | None:
    """(N, LANES) the rays of `lattice_rays` in packets for `VoxelRays.kept_bundle` (flat indices
    probe x rays + ray, -1 for none), or None off a cubic lattice: each packet is one direction from 8
    probes of one interleaved subset (their directions are the same), a 2x2x2 block of its stride-3
    lattice: parallel rays from nearby probes, which Embree traverses together (the seen rays of a
    24^3 lattice 20.8 -> 15.8 ms, the same hits)."""
    side = round(count ** (1.0 / 3.0))
    if side ** 3 != count:
        return None
    sets = interleaved_sets(side)
    index = np.arange(count)
    block = np.stack([index // (side * side), (index // side) % side, index % side], 1) // (2 * INTERLEAVE)
    order = np.lexsort((index, (block[:, 0] * side + block[:, 1]) * side + block[:, 2], sets))
    chunks = []
    for members in np.split(order, np.flatnonzero(np.diff(sets[order])) + 1):   # each subset, 8 probes a row
        chunks.append(np.concatenate([members, np.full(-len(members) % LANES, -1)]).reshape(-1, LANES))
    probes = np.concatenate(chunks)[:, None, :]
    packets = np.where(probes >= 0, probes * rays + np.arange(rays)[None, :, None], -1).reshape(-1, LANES)
    packets.flags.writeable = False
    return packets


INTERLEAVE = 3
"""Probes a side of the blocks whose directions interleave (`interleaved_lattices`): the network's
seen filter is 3x3x3."""


def interleaved_lattices(side: int, rays: int, seed: int) -> np.ndarray:
    """(side^3, rays, 3): the directions of a side^3 probe lattice in its flat order ((i x side + j) x side
    + k, as `viewer.neural.encoding` lays the probes out). One spherical Fibonacci lattice of
    INTERLEAVE^3 x `rays` directions, turned by one random rotation (`seed`), is dealt out in strides:
    probe (i, j, k) takes every INTERLEAVE^3-th direction from offset (i mod 3) + 3 (j mod 3) + 9 (k mod 3).
    Each probe's subset spans the sphere (one direction in each of `rays` bands of equal area), and any
    3x3x3 block of probes holds the whole lattice (interleaved sampling: Keller and Heidrich 2001)."""
    return interleaved_subsets(rays, seed)[interleaved_sets(side)]


def interleaved_subsets(rays: int, seed: int) -> np.ndarray:
    """(INTERLEAVE^3, rays, 3): the subsets of the interleaved lattice, subset s every INTERLEAVE^3-th
    direction from offset s (in `chain_first`'s order)."""
    n = INTERLEAVE ** 3
    whole, _ = sh.sphere_directions(n * rays, seed=seed)
    return chain_first(np.stack([whole[offset::n] for offset in range(n)]))


def chain_first(sets: np.ndarray) -> np.ndarray:
    """(S, R, 3) sets of directions, each along its spiral, reordered so that set s lists first its every
    CHAIN_EVERY-th direction from offset s mod CHAIN_EVERY (the rays the seen light's later bounces
    gather), then the others. On an interleaved lattice each probe's first rays then fall one in each of
    as many bands of heights, and the 27 probes of a 3x3x3 block take evenly spread directions together
    (27 of every 27 x CHAIN_EVERY along the lattice's spiral), which the filter after the gather
    averages."""
    orders = np.stack([np.argsort((np.arange(sets.shape[1]) - s) % CHAIN_EVERY, kind="stable")
                       for s in range(CHAIN_EVERY)])
    return np.ascontiguousarray(np.take_along_axis(sets, orders[np.arange(len(sets)) % CHAIN_EVERY, :, None], axis=1))


def interleaved_sets(side: int) -> np.ndarray:
    """(side^3,) int32: the subset of the interleaved lattice each probe of a side^3 lattice takes,
    (i mod 3) + 3 (j mod 3) + 9 (k mod 3)."""
    i, j, k = np.meshgrid(*[np.arange(side) % INTERLEAVE] * 3, indexing="ij")
    return (i + INTERLEAVE * j + INTERLEAVE * INTERLEAVE * k).reshape(-1).astype(np.int32)


def turned_lattices(count: int, rays: int, seed: int) -> np.ndarray:
    """(count, rays, 3): a spherical Fibonacci lattice of `rays` directions turned by a uniformly random
    rotation per probe (a unit quaternion from a 4D Gaussian), the same for the same seed."""
    lattice, _ = sh.sphere_directions(rays)
    q = np.random.default_rng(seed).normal(size=(count, 4))
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    rotation = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], 1)  # (P, 3, 3)
    return chain_first(np.einsum("pij,rj->pri", rotation, lattice))


GATHER_BLOCK = 64
"""Probes per block of `_gathered`: one buffer of their rays' radiance a block, not one a probe."""


@numba.njit(cache=True, nogil=True, parallel=True, fastmath=True)
def _gathered(voxel, sets, basis, radiance):
    """(P, 9, 3): sum over each probe's rays r of basis[sets[p], :, r] x radiance[voxel[p, r]] (K, 3),
    blocks of probes on every core (an albedo edit gathers SEEN_BOUNCES bounces of RGB). Each probe's
    rays' radiance is read into a buffer, and each coefficient is a dot product along the rays that
    vectorizes; three colours fixed at compile time unroll their loops: 64 rays from a 24^3 lattice
    1.85 -> 1.25 ms on two cores, where the colours were counted at run time."""
    probes, rays = voxel.shape[0], basis.shape[2]   # each probe's first `rays`
    out = np.empty((probes, 9, 3), np.float32)
    for block in numba.prange((probes + GATHER_BLOCK - 1) // GATHER_BLOCK):
        values = np.empty((3, rays), np.float32)
        for p in range(block * GATHER_BLOCK, min(probes, (block + 1) * GATHER_BLOCK)):
            for r in range(rays):
                v = voxel[p, r]
                values[0, r], values[1, r], values[2, r] = radiance[v, 0], radiance[v, 1], radiance[v, 2]
            weights = basis[sets[p]]
            for b in range(9):
                row = weights[b]
                for c in range(3):
                    total = np.float32(0.0)
                    line = values[c]
                    for r in range(rays):
                        total += row[r] * line[r]
                    out[p, b, c] = total
    return out
