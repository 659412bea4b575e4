"""The network's input encoding: the symmetries the design relies on, and the direct-light feature's
physics."""

import numpy as np
import pytest

from scenes import box, ceiling_lamp
from viewer.neural import encoding
from viewer.scene import DirectionalLight, Scene, load
from viewer.rays.voxels import voxelize


def encode(scene: Scene, m: int = 8, n: int = 16) -> encoding.Encoding:
    return encoding.encode_scene(scene, m, n)


def test_shape_and_finite():
    enc = encode(load("cornell"), m=16, n=32)
    assert enc.inputs.shape == (3, encoding.CHANNELS, 16, 16, 16)
    assert np.all(np.isfinite(enc.inputs)) and np.all(enc.scale > 0)


def test_brighter_light_only_changes_the_scale():
    """Transport is linear in the emitted light: the network sees the same input, the output scale doubles."""
    scene = load("cornell")
    brighter = scene.with_emission("light", 2 * scene.emission[scene.face_group == scene.group_index("light")][0])
    a, b = encode(scene), encode(brighter)
    np.testing.assert_allclose(b.scale, 2 * a.scale, rtol=1e-5)
    np.testing.assert_allclose(b.inputs, a.inputs, atol=1e-5)


def test_colour_channels_are_independent():
    """Recolouring a wall in green only changes the green pass: its albedo, and the light it reflects."""
    scene = load("cornell")
    red = scene.group_albedo("red-wall")
    a, b = encode(scene), encode(scene.with_albedo("red-wall", [red[0], 0.6, red[2]]))
    changed = np.abs(b.inputs - a.inputs).reshape(3, encoding.CHANNELS, -1).max(axis=2) > 1e-6
    assert not changed[0].any() and not changed[2].any()
    expected = np.zeros(encoding.CHANNELS, bool)
    expected[encoding.FEATURES.index("albedo")] = True
    expected[encoding.BOUNCE] = expected[encoding.SEEN] = True
    np.testing.assert_array_equal(changed[1], expected)
    # the green wall reflects more green: the bounce's DC grows, most beside the wall, and so does what
    # the probes see of it
    for part in (encoding.BOUNCE, encoding.SEEN):
        more = (b.inputs[1, part][0] - a.inputs[1, part][0])
        assert more.min() >= -1e-6 * np.abs(a.inputs[1, part][0]).max() and more.max() > 0   # float32 rounding
        assert more[0].mean() > more[-1].mean()  # red wall at -x


def test_no_light_gives_zero_scale_and_zero_inputs_of_light():
    enc = encode(box(inward=True, albedo=0.5, name="dark-room"))
    assert np.all(enc.scale == 0)
    assert np.all(enc.inputs[:, encoding.DIRECT] == 0)


def test_sun_reaches_only_the_cells_under_the_window():
    """A closed room with a hole in the ceiling: straight-down sun lights the column under the hole."""
    room = box(inward=True, albedo=0.5, name="room")
    ceiling = np.abs(room.triangles[:, :, 1] - 1.0).max(axis=1) < 1e-9
    walls = Scene("room", room.vertices, room.faces[~ceiling], 0.5, 0.0, 0, ("room",))
    frame = []
    for x0, x1, z0, z1 in ((-1, 1, -1, -0.25), (-1, 1, 0.25, 1), (-1, -0.25, -0.25, 0.25), (0.25, 1, -0.25, 0.25)):
        v = np.array([[x0, 1, z0], [x0, 1, z1], [x1, 1, z1], [x1, 1, z0]], np.float64)  # facing down
        frame.append(Scene("frame", v, np.array([[0, 1, 2], [0, 2, 3]]), 0.5, 0.0, 0, ("ceiling",)))
    sun = DirectionalLight(direction=np.array([0.0, 1.0, 0.0]), irradiance=np.ones(3))
    scene = Scene.concatenate("window", [walls, *frame], sun=sun)
    enc = encode(scene, m=8, n=32)
    visible = enc.inputs[0, encoding.DIRECT.start] > 0  # DC of the direct light: the sun is all there is
    assert visible[3:5, :7, 3:5].all()  # under the hole, all the way down
    assert not visible[0:2, :7, 0:2].any() and not visible[6:8, :7, 6:8].any()  # under the solid ceiling


def test_a_wall_between_the_lamp_and_a_probe_casts_its_shadow():
    """A partition hanging from the ceiling beside the lamp: probes behind it, below the lamp's height,
    get no direct light; the same probes without the partition get it; probes in front keep theirs."""
    lamp = ceiling_lamp(half_size=0.15, height=0.95, radiance=10.0)
    room = box(inward=True, albedo=0.5, name="room")
    v = np.array([[0.4, 1.0, -1.0], [0.4, 1.0, 1.0], [0.4, -0.2, 1.0], [0.4, -0.2, -1.0]])  # x = 0.4, y >= -0.2
    partition = Scene("partition", v, np.array([[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]]), 0.5, 0.0, 0,
                      ("partition",))
    shadowed = encode(Scene.concatenate("shadowed", [room, lamp, partition]), m=8, n=16)
    open_ = encode(Scene.concatenate("open", [room, lamp]), m=8, n=16)

    def direct(enc):
        return enc.inputs[0, encoding.DIRECT.start] * enc.scale[0]

    behind = (slice(6, 8), slice(2, 5), slice(None))   # x > 0.5, y in (-0.5, 0.25): hidden by the partition
    in_front = (slice(2, 6), slice(2, 5), slice(None))
    assert direct(open_)[behind].min() > 0
    assert np.all(direct(shadowed)[behind] == 0)
    np.testing.assert_allclose(direct(shadowed)[in_front], direct(open_)[in_front], rtol=1e-5)


def test_the_bounce_is_the_lit_walls_reflected_light():
    """The bounce feature follows the albedo: black walls reflect nothing, white walls more than twice
    what grey ones do (their light bounces on: every bounce the seen light follows is in it); it is
    there wherever the walls are lit and scaled out like the direct light."""
    lamp = ceiling_lamp(half_size=0.3, height=0.95, radiance=5.0)

    def bounce(albedo):
        enc = encode(Scene.concatenate("room", [box(inward=True, albedo=albedo, name="room"), lamp]), m=8, n=16)
        return enc.inputs[:, encoding.BOUNCE] * enc.scale[:, None, None, None, None], enc

    black, _ = bounce(0.0)
    grey, enc = bounce(0.4)
    white, _ = bounce(0.8)
    assert np.all(black == 0)
    assert grey[:, 0].min() > 0
    ratio = white[:, 0] / grey[:, 0]
    assert ratio.min() > 2.2 and ratio.max() < 2.0 / (1.0 - 0.8)   # walls of 0.8 reflect at most 0.8 a bounce
    # the lamp lights the floor, not the ceiling: the bounce comes from below (Y_1-1 < 0), and most
    # steeply under the dark ceiling
    tilt = grey[0, 1, 4, :, 4] / grey[0, 0, 4, :, 4]
    assert np.all(tilt < 0) and tilt[-1] < tilt[3]


def test_both_sides_of_a_thin_wall_reflect_apart():
    """A thin partition lit on one side reflects that light whether or not its dark back is modelled:
    the back's voxels share cells with the front's, and merged with them into one patch their normals
    cancel and the lit side shines nowhere (the first v3 encoding did this)."""
    assert list(encoding.facings(np.vstack([np.eye(3), -np.eye(3)]))) == [1, 3, 5, 0, 2, 4]
    lamp = ceiling_lamp(half_size=0.15, height=0.95, radiance=10.0)
    room = box(inward=True, albedo=0.5, name="room")
    v = np.array([[0.4, 1.0, -1.0], [0.4, 1.0, 1.0], [0.4, -0.6, 1.0], [0.4, -0.6, -1.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]])
    lit_side = [f for f in faces if np.cross(*(v[f[1:]] - v[f[0]]))[0] < 0]   # facing -x: towards the lamp
    assert len(lit_side) == 2

    def bounce(partition_faces):
        partition = Scene("partition", v, np.array(partition_faces), 0.8, 0.0, 0, ("partition",))
        enc = encode(Scene.concatenate("room", [room, lamp, partition]), m=8, n=16)
        return (enc.inputs[0, encoding.BOUNCE.start] * enc.scale[0])[4:6, 3:7, 2:6]   # just before the partition

    one_sided, two_sided = bounce(lit_side), bounce(faces)
    assert one_sided.min() > 0
    # merged patches would leave the lit side dark. The bounce carries every bounce of the seen light, and
    # the modelled back adds some: the rays from behind meet its front, which reflects the light that
    # reaches the dark side, where the lit side's face alone is black from behind (up to 30% more here,
    # come round the partition's free edge)
    assert np.all(two_sided >= 0.98 * one_sided) and np.all(two_sided <= 1.5 * one_sided)


def test_a_kept_bounce_gathers_only_the_patches_whose_light_changed():
    """`Bounce` kept across albedo edits: the same numbers as a fresh `bounce_sh` after each, while
    gathering only the recoloured group's patches; a change of the direct light gathers them all, and a
    pass left out of `channels` keeps its earlier values."""
    scene = load("cornell")
    lo, hi = scene.bounds
    voxels = voxelize(scene, 16)
    bands = np.array([1.0, 0.1, 0.1, 0.1, 0.05, 0.05, 0.05, 0.05, 0.05])   # a positive DC, small wiggles
    direct = np.random.default_rng(3).random((12 ** 3, 9, 3)) * bands[None, :, None]
    kept = encoding.Bounce(voxels, lo, hi, 12)
    np.testing.assert_allclose(kept.sh(voxels.albedo, direct), encoding.bounce_sh(voxels, direct, lo, hi, 12), rtol=1e-6)
    everything = kept.gathered_patches
    for albedo in [(0.9, 0.1, 0.3), (0.2, 0.7, 0.3), (0.05, 0.05, 0.05)]:
        edited = voxelize(scene.with_albedo("red-wall", albedo), 16)
        assert kept.fits(edited)
        fresh = encoding.bounce_sh(edited, direct, lo, hi, 12)
        np.testing.assert_allclose(kept.sh(edited.albedo, direct), fresh, rtol=1e-5, atol=1e-6 * np.abs(fresh).max())
        assert 0 < kept.gathered_patches < everything / 4
    brighter = 2.0 * direct
    np.testing.assert_allclose(kept.sh(edited.albedo, brighter), 2.0 * fresh, rtol=1e-5, atol=1e-6 * np.abs(fresh).max())
    assert kept.gathered_patches == everything
    only_red = kept.sh(voxels.albedo, brighter, channels=np.array([True, False, False]))
    np.testing.assert_allclose(only_red[..., 0], 2.0 * encoding.bounce_sh(voxels, direct, lo, hi, 12)[..., 0], rtol=1e-5,
                               atol=1e-6 * np.abs(fresh).max())
    np.testing.assert_allclose(only_red[..., 1:], 2.0 * fresh[..., 1:], rtol=1e-5, atol=1e-6 * np.abs(fresh).max())
    assert not kept.fits(voxelize(scene.transformed_group("small-box", np.diag([1.0, 0.5, 1.0, 1.0])), 16))


def test_the_coarse_bounce_is_carried_to_the_probes_trilinearly():
    """`bounce.spread`'s weights carry a coarse lattice's values to the probes: a linear field comes out
    as the same field at the probes between the coarse lattice's outer centres, and each probe's weights
    sum to one (beyond those centres, where the field is held at the faces, too)."""
    from viewer.neural import bounce
    from viewer.probes.grid import ProbeGrid

    lo, hi = np.array([-1.0, -0.5, -2.0]), np.array([1.5, 1.0, 2.0])
    weights = bounce.spread(tuple(lo), tuple(hi), 24, 12)
    coarse = ProbeGrid.positions_for(lo, hi, 12).reshape(-1, 3)
    fine = ProbeGrid.positions_for(lo, hi, 24).reshape(-1, 3)
    field = np.column_stack([coarse @ [1.0, -2.0, 0.5] + 3.0, np.ones(len(coarse))])
    out = bounce.spread_onto(weights, field)
    np.testing.assert_allclose(out[:, 1], 1.0, rtol=1e-12)
    inside = np.all((fine >= coarse.min(axis=0)) & (fine <= coarse.max(axis=0)), axis=1)
    assert inside.mean() > 0.7   # (22 / 24)^3
    np.testing.assert_allclose(out[inside, 0], fine[inside] @ [1.0, -2.0, 0.5] + 3.0, rtol=1e-12, atol=1e-12)


def test_the_bounce_gather_of_any_surface_light():
    """`Bounce.gathered` gathers the light the voxels leave with as the bounce does: given each voxel's
    albedo x its irradiance from the direct light / pi it is the bounce; it is linear, and a surface
    light of zero gives zero; 1-cell patches on the probes' own lattice gather the same light."""
    scene = load("cornell")
    lo, hi = scene.bounds
    voxels = voxelize(scene, 16)
    bands = np.array([1.0, 0.1, 0.1, 0.1, 0.05, 0.05, 0.05, 0.05, 0.05])
    direct = np.random.default_rng(4).random((12 ** 3, 9, 3)) * bands[None, :, None]
    bounce = encoding.Bounce(voxels, lo, hi, 12)
    expected = bounce.sh(voxels.albedo, direct)
    leaving = voxels.albedo * bounce._leaving_per_albedo
    np.testing.assert_allclose(bounce.gathered(leaving), expected, rtol=1e-6, atol=1e-9 * np.abs(expected).max())
    np.testing.assert_allclose(bounce.gathered(3.0 * leaving), 3.0 * expected, rtol=1e-5, atol=1e-6 * np.abs(expected).max())
    assert not np.any(bounce.gathered(np.zeros_like(leaving)))
    fine = encoding.Bounce(voxels, lo, hi, 12, patch=1, lattice=1).gathered(leaving)
    # the same light in all: the DC summed over the probes agrees to a few percent
    assert abs(fine[:, 0].sum() / expected[:, 0].sum() - 1.0) < 0.1


def test_the_bounce_floor_scores_each_gather_by_its_best_gain():
    """viewer.training.bounce_floor: a target that is the gather of the solver's converged surface light
    scores 0 for that gather, any gain of it too, and no gather scores above 100% (a gain of 0 does)."""
    from types import SimpleNamespace

    from viewer.physical.gi import GISettings, PhysicalGI
    from viewer.training import bounce_floor

    scene = load("cornell")
    lo, hi = scene.bounds
    solver = PhysicalGI(GISettings(voxels=16, probes=8))
    solver.update(scene)
    grid = voxelize(scene, 16)
    gathered = encoding.Bounce(grid, lo, hi, 8).gathered(solver.lighting.reflected.astype(np.float64))
    target = 2.5 * gathered.reshape(8, 8, 8, 9, 3).transpose(4, 3, 0, 1, 2)
    example = SimpleNamespace(scene=scene, lo=np.asarray(lo), hi=np.asarray(hi), path="cornell")
    errors = bounce_floor.room_errors(example, target, np.ones((8, 8, 8), bool), 8, 16, full=False)
    assert errors["converged surface light"] < 1e-6
    assert all(0.0 <= e <= 1.0 + 1e-9 for e in errors.values())
    assert errors["bounce input"] > 0.01


def test_the_seen_bounce_stops_at_a_wall():
    """A wall from floor to ceiling splits the room; the lamp lights one side. The unshadowed bounce
    reaches through the wall (half its open-room value), the seen bounce does not: the probes behind
    the wall see only surfaces the lamp cannot reach. Without the wall both see the same light: the seen
    one carries it on through every bounce, about twice the one bounce in a room of albedo 0.5.

    The wall is a voxel thick or more. A thinner one shares its voxels' cells with both sides, and the
    voxels of its dark side read the lit side's probes back (`bounce.READ_BACK`): a two-sided sheet, or a
    closed panel 2 cm thick, passes three quarters of the open room's seen light on this lattice of 8^3
    probes and 16^3 voxels."""
    lamp = ceiling_lamp(half_size=0.15, height=0.95, radiance=10.0)
    room = box(inward=True, albedo=0.5, name="room")
    wall = box(half_size=np.array([0.075, 1.0, 1.0]), centre=(0.425, 0.0, 0.0), albedo=0.8, name="wall")

    def behind(scene):   # the DC of both bounces at the probes with x > 0.5
        enc = encode(scene, m=8, n=16)
        dc = [enc.inputs[0, part.start, 6:].mean() * enc.scale[0] for part in (encoding.BOUNCE, encoding.SEEN)]
        return dc[0], dc[1]

    bounce, seen = behind(Scene.concatenate("split", [room, lamp, wall]))
    open_bounce, open_seen = behind(Scene.concatenate("open", [room, lamp]))
    assert 1.0 < open_seen / open_bounce < 4.0
    assert bounce > 0.3 * open_bounce
    assert seen < 0.1 * open_seen and seen < 0.5 * bounce


@pytest.mark.parametrize("name", ["cornell", "paper-test"])
def test_the_seen_rays_land_where_the_solvers_do(name):
    """The seen rays' listing, remade from a voxel grid alone, names the voxels that the listing made
    with the voxelization's own keys names."""
    from viewer.rays import dda
    from viewer.rays.voxels import voxelize_with_faces

    scene = load(name)
    voxelization = voxelize_with_faces(scene, 24)
    ours = encoding.landing_cells(scene, voxelization.grid)
    theirs = dda.Cells.of(voxelization, scene)
    np.testing.assert_array_equal(ours.voxel, theirs.voxel)
    np.testing.assert_array_equal(ours.triangle, theirs.triangle)


@pytest.mark.parametrize("albedo", [0.5, 0.9])
def test_the_seen_light_carries_every_bounce_of_a_closed_room(monkeypatch, albedo):
    """In a closed room of one albedo a, each bounce reflects a of the light before it and nothing leaves:
    all the bounces sum to the first over (1 - a). The seen light gathers three and adds the rest as a
    geometric tail whose ratio it measures on the voxels: about a, and the sum about the first bounce
    over (1 - a), where three bounces alone would give 1 + a + a^2 (2.71 where the truth is 10 at 0.9)."""
    from viewer.neural import seen

    calls = []
    monkeypatch.setattr(encoding, "seen_light", lambda *args: calls.append(args) or seen.seen_light(*args))
    lamp = ceiling_lamp(half_size=0.15, height=0.95, radiance=10.0)
    encode(Scene.concatenate("closed", [box(inward=True, albedo=albedo, name="room"), lamp]), m=8, n=16)
    rays, once, voxel_albedo, leaving = calls[0]
    first = rays.gathered(leaving)[:, 0].mean()
    reflected = once.reflected(voxel_albedo, rays.gathered(leaving))
    assert abs(seen.tail_ratio(once.area, reflected, leaving).mean() - albedo) < 0.08
    every = seen.seen_light(rays, once, voxel_albedo, leaving)[0][:, 0].mean()
    assert every / first == pytest.approx(1.0 / (1.0 - albedo), rel=0.2)


def test_the_seen_filter_stops_at_a_wall():
    """`SeenRays.filtered`, which the further bounces read the seen light through: the open-weighted
    3x3x3 box of the probes, where a neighbour across a surface counts as the probe itself. Light on
    one side of a wall from floor to ceiling stays on that side; with no wall it is the plain
    open-weighted box (the lattice's faces repeated outward)."""
    from scipy import ndimage

    from viewer.probes.grid import ProbeGrid

    room = box(inward=True, albedo=0.5, name="room")
    v = np.array([[0.4, 1.0, -1.0], [0.4, 1.0, 1.0], [0.4, -1.0, 1.0], [0.4, -1.0, -1.0]])
    wall = Scene("wall", v, np.array([[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]]), 0.8, 0.0, 0, ("wall",))
    for scene, walled in ((Scene.concatenate("split", [room, wall]), True), (room, False)):
        lo, hi = scene.bounds
        grid = voxelize(scene, 16)
        points = ProbeGrid.positions_for(lo, hi, 8).reshape(-1, 3)
        rays = encoding.seen_rays(encoding.occluders(scene, grid), grid, points)
        light = np.zeros((len(points), 9, 2), np.float32)
        light[points[:, 0] < 0.4, 0, 0] = 1.0
        light[:, :, 1] = np.random.default_rng(5).random((len(points), 9))
        out = rays.filtered(light)
        if walled:
            assert not rays.links[0].all() and rays.links[1:].all()
            np.testing.assert_array_equal(out[points[:, 0] > 0.4, 0, 0], 0.0)
            np.testing.assert_allclose(out[points[:, 0] < 0.4, 0, 0], 1.0, rtol=1e-6)
        else:
            assert rays.links.all()
            w = rays.open.reshape(8, 8, 8).astype(np.float64)
            num = ndimage.uniform_filter(light.reshape(8, 8, 8, 18) * w[..., None], size=(3, 3, 3, 1), mode="nearest")
            den = np.maximum(ndimage.uniform_filter(w, size=3, mode="nearest"), 1.0 / 27.0)
            np.testing.assert_allclose(out, (num / den[..., None]).reshape(out.shape), rtol=1e-5, atol=1e-6)


def test_the_compressed_light_is_asinh_of_it():
    """`compressed`'s compiled asinh against numpy's, over the light's range and past it (zero, signs,
    the smallest and a square that would overflow), the features it leaves alone as they were."""
    rng = np.random.default_rng(3)
    shape = (3, encoding.CHANNELS, 6, 6, 6)
    inputs = (rng.normal(size=shape) * np.exp(4 * rng.normal(size=shape))).astype(np.float32)
    inputs[0, encoding.DIRECT.start, 0, 0, :5] = [0.0, -4e-3, 1e-30, 3e20, -6e-3]
    out = encoding.compressed(inputs)
    expected = inputs.copy()
    for part in encoding.COMPRESSED:
        expected[:, part] = np.arcsinh(inputs[:, part])
    assert np.allclose(out, expected, rtol=3e-5, atol=0)
    assert np.array_equal(out[:, encoding.OPEN], inputs[:, encoding.OPEN])
    assert np.all(np.sign(out) == np.sign(inputs))
    # given an earlier call, equal rows are copied from its answer and the others computed: an edit of
    # one row (one value of it) gives what a fresh call gives
    edited = inputs.copy()
    edited[1, encoding.SEEN.start, 2, 3, 4] *= 2.0
    edited[2, encoding.OPEN] = 0.5
    np.testing.assert_array_equal(encoding.compressed(edited, (inputs, out)), encoding.compressed(edited))
    marked = out.copy()
    marked[0, encoding.DIRECT.start] = -1.0   # a kept row comes from the earlier answer, not computed again
    again = encoding.compressed(edited, (inputs, marked))
    assert np.all(again[0, encoding.DIRECT.start] == -1.0)
    np.testing.assert_array_equal(encoding.compressed(edited, (inputs[:2], out[:2])), encoding.compressed(edited))


def test_the_compressed_light_holds_across_the_floats_range():
    """The hand-taken logarithm of `compressed` against numpy's asinh at every power of two a float holds
    and on either side of each (where the mantissa wraps, and where it is halved past sqrt 2), to the
    largest float, with infinities and NaN kept."""
    powers = 2.0 ** np.arange(-7, 128)
    values = np.concatenate([powers, powers * np.sqrt(2.0), np.geomspace(5e-3, 3e38, 5000)]).astype(np.float32)
    values = np.concatenate([values, np.nextafter(values, np.float32(0)), np.nextafter(values, np.float32(np.inf))])
    values = values[np.isfinite(values)]
    cells = 216 * int(np.ceil((len(values) + 3) / 216))
    inputs = np.zeros((1, encoding.CHANNELS, cells), np.float32)
    row = np.zeros(cells, np.float32)
    row[:len(values)] = values
    row[len(values):len(values) + 3] = [np.inf, -np.inf, np.nan]
    inputs[0, encoding.SEEN.start] = row
    out = encoding.compressed(inputs.reshape(1, encoding.CHANNELS, -1, 6, 6)).reshape(inputs.shape)
    got = out[0, encoding.SEEN.start]
    expected = np.arcsinh(values.astype(np.float64))
    np.testing.assert_allclose(got[:len(values)], expected, rtol=3e-5, atol=0)
    past_one = values >= 1.0   # where the sum does not round: two ulps
    np.testing.assert_allclose(got[:len(values)][past_one], expected[past_one], rtol=2.5e-7, atol=0)
    assert got[len(values)] == np.inf and got[len(values) + 1] == -np.inf and np.isnan(got[len(values) + 2])
