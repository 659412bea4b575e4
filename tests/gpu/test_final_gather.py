"""The final gather of the baked indirect light (viewer/gpu/final_gather.py): where its rays land in the
lightmap, and that their sum is the irradiance integral."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import box, CUBE_QUADS

from viewer.rays import dda
from viewer.rays.cast import TriangleCaster, embree_available
from viewer.gpu.final_gather import GatherRays
from viewer.physical.geometry import voxelize_with_faces
from viewer.gpu.direct_bake import lightmap_layout, lightmap_texels
from viewer.scene import Scene, load

TEXEL = 0.05


BACKENDS = [pytest.param("embree", marks=pytest.mark.skipif(not embree_available(), reason="no embreex")), "dda"]


def gather(scene: Scene, points, normals, rays: int = 72, seed: int = 0, backend: str | None = None):
    """The rays of the samples, and the lightmap's texel positions ((H, 2W, 3): front | back), cast by
    `backend` (None: Embree where it is installed)."""
    origin, n, size = lightmap_layout(scene, TEXEL)
    keep = scene.face_areas > 0
    face_tile = np.where(keep, np.cumsum(keep) - 1, -1)
    cells = dda.Cells.of(voxelize_with_faces(scene, 16), scene)
    caster = TriangleCaster(scene, cells, backend)
    rays = GatherRays.of(np.asarray(points, np.float64), np.asarray(normals, np.float64), caster, face_tile, origin,
                         n, size[0], 1e-6, rays, seed)
    position = lightmap_texels(scene, origin, n, size)[0][..., :3]
    return rays, np.concatenate([position, position], axis=1)


def open_top_room() -> Scene:
    """The closed room of half size 1 without its ceiling (CUBE_QUADS[3], y = 1)."""
    room = box(inward=True, albedo=0.5)
    keep = np.ones(len(room.faces), bool)
    keep[[3, 3 + len(CUBE_QUADS)]] = False            # quads_to_triangles: first halves, then second
    assert np.allclose(room.vertices[room.faces[~keep]][..., 1], 1.0)
    return Scene("open", room.vertices, room.faces[keep], room.albedo[keep], room.emission[keep],
                 room.face_group[keep], room.groups)


def floor_points(count: int, spread: float = 0.0, seed: int = 0):
    rng = np.random.default_rng(seed)
    points = np.column_stack([rng.uniform(-spread, spread, count), np.full(count, -1.0),
                              rng.uniform(-spread, spread, count)])
    return points, np.tile([0.0, 1.0, 0.0], (count, 1))


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_closed_room_sends_every_ray_back_and_the_sum_is_what_it_reflects(backend):
    """In a closed room every ray lands on a texel, so a lightmap that reflects 1 everywhere gives
    irradiance 1 (the furnace), and 0.3 where the room reflects 0.3."""
    scene = box(inward=True, albedo=0.5)
    rays, position = gather(scene, *floor_points(300, spread=0.9), backend=backend)
    assert (rays.hits >= 0).all()
    landing = len(rays.landing[0])               # what the pixels the rays land on reflect
    np.testing.assert_allclose(rays.irradiance(np.ones((landing, 3), np.float32)), 1.0, rtol=1e-6)
    np.testing.assert_allclose(rays.irradiance(np.full((landing, 3), 0.3, np.float32)), 0.3, rtol=1e-5)


@pytest.mark.parametrize("backend", BACKENDS)
def test_rays_out_of_an_open_side_bring_nothing_and_the_rest_is_the_form_factor(backend):
    """From the centre of the floor of a room without a ceiling, the cosine-weighted share of the
    hemisphere that escapes is the form factor to the opening, 0.2394 (a point to a parallel 2 x 2
    square 2 above its centre: four corner rectangles of A = B = 1/2). Each sample shifts its strata at
    random, so their mean converges to the integral (a fixed pattern would err alike on every sample)."""
    rays, position = gather(open_top_room(), *floor_points(400), backend=backend)
    escaped = (rays.hits == -1).mean()
    a = b = 0.5
    corner = (a / np.sqrt(1 + a * a) * np.arctan(b / np.sqrt(1 + a * a))
              + b / np.sqrt(1 + b * b) * np.arctan(a / np.sqrt(1 + b * b))) / (2 * np.pi)
    assert escaped == pytest.approx(4 * corner, abs=0.006)
    light = rays.irradiance(np.ones((len(rays.landing[0]), 3), np.float32))
    assert light.mean() == pytest.approx(1.0 - 4 * corner, abs=0.006)


def texel_samples(scene: Scene, count: int, seed: int):
    """Points and normals of `count` lightmap texels picked at random over the scene's surfaces."""
    origin, n, size = lightmap_layout(scene, TEXEL)
    texels, normals, *_ = lightmap_texels(scene, origin, n, size)
    covered = texels[..., 3] > 0
    pick = np.random.default_rng(seed).choice(int(covered.sum()), count, replace=False)
    return texels[covered][pick, :3].astype(np.float64), normals[covered][pick, :3].astype(np.float64)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_ray_lands_on_the_texel_of_the_surface_it_hits(backend):
    """Texel-accurate hits in the Cornell box: each texel a sample's ray lands on lies in front of the
    sample, and the segment to it is clear, but for a few grazing rays that land a texel off a corner."""
    scene = load("cornell")
    points, normals = texel_samples(scene, 300, seed=1)
    rays, position = gather(scene, points, normals, rays=32, backend=backend)
    sample, ray = np.nonzero(rays.hits >= 0)
    landed = position.reshape(-1, 3)[rays.hits[sample, ray]]
    ahead = np.einsum("ij,ij->i", landed - points[sample], normals[sample])
    assert (ahead > 0).mean() > 0.99
    toward = points[sample] + 0.97 * (landed - points[sample])       # stop short of the surface landed on
    clear = dda.segments_clear(dda.Cells.of(voxelize_with_faces(scene, 32), scene),
                               points[sample] + 1e-5 * normals[sample], toward)
    assert clear.mean() > 0.98


@pytest.mark.skipif(not embree_available(), reason="no embreex")
def test_embree_and_the_dda_land_the_rays_on_the_same_texels():
    """The same gather rays from texels all over the Cornell box land on the same lightmap pixel through
    either caster, but for the few that pass within float32's precision of an edge or a texel's border,
    or meet the bottom of a box where it lies on the floor (two faces at the same distance)."""
    scene = load("cornell")
    points, normals = texel_samples(scene, 500, seed=2)
    embree = gather(scene, points, normals, backend="embree")[0].hits
    marched = gather(scene, points, normals, backend="dda")[0].hits
    assert (embree == marched).mean() > 0.997


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_ray_that_meets_the_back_of_a_face_reads_its_back_side(backend):
    """A one-sided wall across a closed room, its front towards +x: rays from a point facing it from
    -x meet its back, and read the back sides' half of the lightmap (the right half)."""
    wall = np.array([[0.02, -1, -1], [0.02, 1, -1], [0.02, 1, 1], [0.02, -1, 1]], np.float64)
    partition = Scene("partition", wall, np.array([[0, 1, 2], [0, 2, 3]]), 0.5, 0.0, 0, ("partition",))
    assert (partition.face_normals[:, 0] > 0.99).all()
    scene = Scene.concatenate("partitioned", [box(inward=True, albedo=0.5, name="room"), partition])
    rays, position = gather(scene, np.tile([-0.5, 0.0, 0.0], (20, 1)), np.tile([1.0, 0.0, 0.0], (20, 1)),
                            backend=backend)
    width = position.shape[1] // 2
    assert (rays.hits >= 0).all()
    back = rays.hits % (2 * width) >= width
    assert back.mean() > 0.75           # the partition fills the view but for grazing rays to the side walls
    pixels = position.shape[0] * position.shape[1]
    reflected = np.zeros((position.shape[0], 2 * width, 3), np.float32)
    reflected[:, width:] = 2.0                                       # back sides reflect 2, fronts 0
    landed = reflected.reshape(pixels, 3)[rays.landing[0]]
    assert rays.irradiance(landed).mean() == pytest.approx(2.0 * back.mean(), rel=1e-5)


def test_ray_counts_must_fill_the_grid_of_strata():
    """A truncated grid of strata leans towards the normal (2% more cos theta at 64 rays): refused."""
    with pytest.raises(ValueError, match="2 r"):
        gather(box(inward=True), *floor_points(2), rays=64)


@pytest.mark.parametrize("where", [(0.0, 0.9, 0.0), (0.7, -0.2, 0.4), (0.0, -0.99, 0.0)])
def test_the_moved_faces_sphere_skips_only_rays_that_cannot_meet_them(where):
    """`_affected` skips rays (and rows of strata) that cannot meet the moved triangles' bounding sphere;
    what it marks is exactly what it marks with a sphere that skips nothing, for samples all around the
    triangles (near them, under them, on their plane)."""
    from viewer.gpu import final_gather

    rng = np.random.default_rng(5)
    count = 400
    points = rng.uniform(-1.0, 1.0, (count, 3))
    normals = rng.normal(size=(count, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    corners = np.array(where) + np.array([[[-0.1, 0, -0.1], [0.1, 0, -0.1], [0.1, 0, 0.1]],
                                          [[-0.1, 0, -0.1], [0.1, 0, 0.1], [-0.1, 0.05, 0.1]]])
    points[:10] = corners[0, 0] + rng.uniform(-0.02, 0.02, (10, 3))      # a few right next to them
    frame = final_gather._Frame.of(points, normals, 72, 0)
    hits = rng.integers(-1, 50, (count, 72)).astype(np.int32)
    pixel_points = rng.uniform(-1.0, 1.0, (50, 3))
    v0, e1, e2 = corners[:, 0].copy(), corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    sample_moved, pixel_moved = rng.random(count) < 0.02, rng.random(50) < 0.1   # some rays marked anyway
    args = (*frame.args(0.0), hits, sample_moved, pixel_moved, pixel_points, v0, e1, e2, 0.01)
    sphere = final_gather._bounding_sphere(v0, e1, e2)
    culled = final_gather._affected(*args, sphere)
    everything = final_gather._affected(*args, (0.0, 0.0, 0.0, 1e6))
    assert 0 < culled.sum() < culled.size
    np.testing.assert_array_equal(culled, everything)
    assert culled[sample_moved].all() and culled[np.isin(hits, np.flatnonzero(pixel_moved))].all()


@pytest.mark.parametrize("backend", BACKENDS)
def test_samples_that_look_out_of_the_room_are_not_cast_and_land_as_if_they_were(backend, monkeypatch):
    """The backs of a room's walls look out of the scene: their rays are not cast (`nothing_ahead`), and
    the hits are those that casting every ray gives, on the Cornell box's walls, floor and boxes alike."""
    from viewer.gpu import final_gather

    scene, points, normals, _ = cornell_samples(400, 4)   # both sides
    cells = dda.Cells.of(voxelize_with_faces(scene, 16), scene)
    caster = TriangleCaster(scene, cells, backend)
    outward = caster.nothing_ahead(points, normals, 1e-6)
    lo, hi = scene.bounds
    on_bounds = (np.abs(points - lo) < 1e-6) | (np.abs(points - hi) < 1e-6)
    assert 0.1 < outward.mean() < 0.5                 # the walls' backs, none of their fronts or the boxes'
    assert on_bounds[outward].any(axis=1).all()
    sent = []
    counting = caster.closest_hits
    monkeypatch.setattr(caster, "closest_hits", lambda o, d, t=np.inf: sent.append(len(o)) or counting(o, d, t))
    landing = final_gather.land_grid     # Embree's rays made and cast in one compiled loop: (samples, rays)
    monkeypatch.setattr(final_gather, "land_grid", lambda *a: sent.append(len(a[8]) * len(a[9])) or landing(*a))
    skipped, _ = gather_with(caster, scene, points, normals)
    cast_all = sum(sent)
    monkeypatch.setattr(caster, "nothing_ahead", lambda p, n, m: np.zeros(len(p), bool))
    sent.clear()
    every, _ = gather_with(caster, scene, points, normals)
    np.testing.assert_array_equal(skipped.hits, every.hits)
    assert (skipped.hits[outward] == final_gather.ESCAPED).all()
    assert cast_all < sum(sent) - 0.9 * outward.sum() * 72


def test_a_point_sees_nothing_ahead_only_where_no_face_reaches_past_its_plane():
    scene = box(inward=True, albedo=0.5)          # the cube of half size 1
    caster = TriangleCaster.marching(dda.Cells.of(voxelize_with_faces(scene, 8), scene))
    points = np.array([[0.0, -1.0, 0.0], [0.0, -1.0, 0.0], [0.0, -0.99, 0.0], [0.5, -1.0, 0.5], [0.0, 1.0, 0.0]])
    normals = np.array([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.1, -0.995, 0.0], [0.0, 1.0, 0.0]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    np.testing.assert_array_equal(caster.nothing_ahead(points, normals, 1e-9), [True, False, False, False, True])


def gather_with(caster: TriangleCaster, scene: Scene, points, normals, rays: int = 72):
    origin, n, size = lightmap_layout(scene, TEXEL)
    keep = scene.face_areas > 0
    face_tile = np.where(keep, np.cumsum(keep) - 1, -1)
    return GatherRays.of(points, normals, caster, face_tile, origin, n, size[0], 1e-5, rays), size


def test_a_caster_started_early_serves_its_own_scene_only():
    """The renderer starts the gather's caster while it lays the lightmap out (`caster_of`'s `early`): the
    worker takes that one for the scene it was started for, and makes its own for any other."""
    from concurrent.futures import Future

    from viewer.gpu.gather_cast import caster_of

    scene, other = load("cornell"), load("paper-test")
    early = Future()
    early.set_result("the early caster")
    assert caster_of(scene, (scene, early)) == "the early caster"
    assert isinstance(caster_of(other, (scene, early)), TriangleCaster)


def cornell_samples(count: int, seed: int):
    """Random points on the Cornell box's faces, both sides, with their normals and faces."""
    scene = load("cornell")
    rng = np.random.default_rng(seed)
    faces = rng.integers(0, len(scene.faces), count)
    u, v = rng.random((2, count))
    flip = u + v > 1
    u, v = np.where(flip, 1 - u, u), np.where(flip, 1 - v, v)
    corners = scene.triangles[faces]
    points = corners[:, 0] + u[:, None] * (corners[:, 1] - corners[:, 0]) + v[:, None] * (corners[:, 2] - corners[:, 0])
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return scene, np.concatenate([points, points]), np.concatenate([normals, -normals]), np.concatenate([faces, faces])


@pytest.mark.parametrize("backend", BACKENDS)
def test_coarse_samples_cast_half_their_rays_and_repeat_the_rest(backend, monkeypatch):
    """A coarse sample casts its even strata and its scouts, the rays a full gather casts there, and each
    other ray repeats the one before it in its row (unless the sample is enclosed: then every ray repeats
    a scout); the other samples' rays are the full gather's. A move then gives what gathering the moved
    scene afresh gives, coarse samples alike."""
    from viewer.gpu import final_gather

    scene, points, normals, faces = cornell_samples(300, 7)
    coarse = np.random.default_rng(8).random(len(points)) < 0.5
    origin, n, size = lightmap_layout(scene, TEXEL)
    keep = scene.face_areas > 0
    layout = (np.where(keep, np.cumsum(keep) - 1, -1), origin, n, size[0], 1e-5)
    caster = TriangleCaster(scene, dda.Cells.of(voxelize_with_faces(scene, 16), scene), backend)
    sent = []
    counting = caster.closest_hits
    monkeypatch.setattr(caster, "closest_hits", lambda o, d, t=np.inf: sent.append(len(o)) or counting(o, d, t))
    landing = final_gather.land_grid
    monkeypatch.setattr(final_gather, "land_grid", lambda *a: sent.append(len(a[8]) * len(a[9])) or landing(*a))
    full = GatherRays.of(points, normals, caster, *layout, 72)
    all_rays, sent[:] = sum(sent), []
    half = GatherRays.of(points, normals, caster, *layout, 72, coarse=coarse)
    cast, repeated = final_gather.paired_rays(72)
    assert len(cast) == 40 and (repeated % 2 == 1).all() and np.isin(final_gather.scout_rays(72), cast).all()
    np.testing.assert_array_equal(half.hits[~coarse], full.hits[~coarse])
    np.testing.assert_array_equal(half.hits[np.ix_(coarse, cast)], full.hits[np.ix_(coarse, cast)])
    paired = coarse & ~final_gather._all_backs(full.hits[:, final_gather.scout_rays(72)], size[0])
    assert paired.sum() > 0.3 * len(points)   # the others are enclosed: their rays repeat the scouts'
    np.testing.assert_array_equal(half.hits[np.ix_(paired, repeated)], half.hits[np.ix_(paired, repeated - 1)])
    outward = caster.nothing_ahead(points, normals, 0.5e-5)   # these cast none
    assert sum(sent) == all_rays - 32 * (paired & ~outward).sum()

    box_faces = np.flatnonzero(scene.face_group == scene.groups.index("large-box"))
    moved_vertices = scene.vertices.copy()
    moved_vertices[np.unique(scene.faces[box_faces])] += [0.03, 0.0, 0.02]
    moved = Scene(scene.name, moved_vertices, scene.faces, scene.albedo, scene.emission, scene.face_group,
                  scene.groups)
    moved_faces = np.flatnonzero(np.any(scene.triangles[keep] != moved.triangles[keep], axis=(1, 2)))
    assert 0 < len(moved_faces) < keep.sum()
    position, _, tile, _ = lightmap_texels(scene, origin, n, size)
    pixel_points = np.concatenate([position[..., :3], position[..., :3]], axis=1).reshape(-1, 3)
    pixel_moved = np.isin(np.concatenate([tile, tile], axis=1).ravel(), moved_faces)
    moved_points = points.copy()
    sample_moved = np.isin(faces, np.flatnonzero(keep)[moved_faces])
    assert sample_moved.any() and np.isin(faces[sample_moved], box_faces).all()
    moved_points[sample_moved] += [0.03, 0.0, 0.02]
    moved_caster = TriangleCaster(moved, dda.Cells.of(voxelize_with_faces(moved, 16), moved), backend)
    landed = half.landing[0]
    after = half.after_moving(sample_moved, pixel_moved[landed], pixel_points[landed], moved.triangles[keep][moved_faces],
                              2.0 * TEXEL, moved_points, normals, moved_caster, *layout)
    afresh = GatherRays.of(moved_points, normals, moved_caster, *layout, 72, coarse=coarse)
    np.testing.assert_array_equal(after.hits, afresh.hits)
    np.testing.assert_array_equal(after.coarse, coarse)
