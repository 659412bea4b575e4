"""The direct light at the probes (viewer/neural/direct.py): a lamp's solid angle, its pieces and quarters
near a probe, and the compiled gather of every patch at every probe."""

from dataclasses import replace

import numpy as np
import pytest

from scenes import box, ceiling_lamp
from viewer.neural import encoding
from viewer.probes import sh
from viewer.rays.voxels import voxelize
from viewer.scene import Scene


def test_direct_feature_is_the_lamps_solid_angle():
    """A small lamp straight above a probe in an open scene: the DC of the unshadowed feature equals
    L * A * cos / r^2 * Y00 within the near-field clamp's error."""
    lamp = ceiling_lamp(half_size=0.05, height=0.95, radiance=10.0)
    scene = Scene.concatenate("lamp-above-floor", [lamp, box(half_size=1.0, centre=(0, -2.0, 0), name="block")])
    voxels = voxelize(scene, 32)
    probe = np.array([[0.0, -0.05, 0.0]])
    lights = encoding.emitting_patches(np.zeros(voxels.count, np.int64), voxels)
    value = encoding.emitter_sh(lights, probe)[0, 0, 0]
    r = 1.0
    expected = 10.0 * 0.01 / (r * r) * sh.basis(np.array([0.0, 1.0, 0.0]))[0]
    assert value == pytest.approx(expected, rel=0.02)


def test_a_probe_near_a_lamp_sums_its_pieces():
    """A probe 0.2 below a lamp 0.4 wide: one term for the whole lamp misjudges its solid angle; the
    lamp's pieces (the voxels' light samples) within `near` of the probe give it within 2%."""
    lamp = ceiling_lamp(half_size=0.2, height=0.95, radiance=10.0)
    scene = Scene.concatenate("lamp-above-floor", [lamp, box(half_size=1.0, centre=(0, -2.0, 0), name="block")])
    voxels = voxelize(scene, 32)
    probe = np.array([[0.0, 0.75, 0.0]])
    cell = np.zeros(voxels.count, np.int64)   # one patch: the whole lamp
    lights = encoding.emitting_patches(cell, voxels)
    pieces = encoding.patch_pieces(cell, voxels, lights[3], near=1.0)
    assert len(lights[2]) == 1 and pieces.start.tolist() == [0, len(pieces.area)] and len(pieces.area) > 16
    u = (np.arange(400) + 0.5) / 400 * 0.4 - 0.2   # the solid angle: cos dA / r^2 over a fine grid
    x, z = np.meshgrid(u, u)
    solid_angle = float(np.sum(0.2 / (x * x + 0.04 + z * z) ** 1.5) * (0.4 / 400) ** 2)
    expected = 10.0 * solid_angle * sh.basis(np.array([0.0, 1.0, 0.0]))[0]
    whole = encoding.emitter_sh(lights, probe)[0, 0, 0]
    summed = encoding.emitter_sh(lights, probe, pieces=pieces)[0, 0, 0]
    assert summed == pytest.approx(expected, rel=0.02)
    assert abs(whole - expected) > 5 * abs(summed - expected)
    # beyond `near` the lamp is one term again
    far = np.array([[0.0, -0.5, 0.0]])
    np.testing.assert_allclose(encoding.emitter_sh(lights, far, pieces=pieces), encoding.emitter_sh(lights, far))


def test_between_near_all_and_near_a_probe_sums_the_lamps_quarters():
    """A lamp one patch wide (0.4, `near` NEAR_PIECES patches), a probe 1.35 below it: past NEAR_ALL
    patches, it sums the lamp's four quarters, within 1% of the pieces' sum, which one term misses by
    more; the quarters keep the pieces' area and power."""
    from viewer.neural.direct import NEAR_ALL, NEAR_PIECES, quartered

    lamp = ceiling_lamp(half_size=0.2, height=0.95, radiance=10.0)
    scene = Scene.concatenate("lamp-above-floor", [lamp, box(half_size=1.0, centre=(0, -2.0, 0), name="block")])
    voxels = voxelize(scene, 32)
    cell = np.zeros(voxels.count, np.int64)
    lights = encoding.emitting_patches(cell, voxels)
    pieces = encoding.patch_pieces(cell, voxels, lights[3], near=0.4 * NEAR_PIECES)
    quarters = quartered(pieces, lights[0], lights[1])
    assert quarters.start.tolist() == [0, 4]
    assert quarters.area.sum() == pytest.approx(pieces.area.sum())
    assert np.sum(quarters.area * quarters.gain) == pytest.approx(np.sum(pieces.area * pieces.gain))
    probe = np.array([[0.05, -0.4, -0.03]])
    assert 0.4 * NEAR_ALL < np.linalg.norm(probe - lights[0]) < 0.4 * NEAR_PIECES
    summed = encoding.emitter_sh(lights, probe, pieces=pieces)[0, :, 0]
    every = encoding.emitter_sh(lights, probe, pieces=replace(pieces, near=10.0))[0, :, 0]   # all pieces
    whole = encoding.emitter_sh(lights, probe)[0, :, 0]
    assert np.abs(summed - every).max() < 0.01 * every[0]
    assert np.abs(whole - every).max() > 2 * np.abs(summed - every).max()


def test_each_patch_s_pieces_merge_by_quarter():
    """`quartered` against the merge written out per patch and quarter: random patches facing each axis,
    one with no pieces, one whose pieces all lie in one quarter, one whose pieces are dark (its quarter
    then sits at the centre of area)."""
    from viewer.neural.direct import Pieces, quartered

    rng = np.random.default_rng(5)
    counts = [7, 0, 12, 5, 9]
    centre, normal = rng.normal(size=(5, 3)), np.eye(3)[[0, 1, 2, 0, 1]] * [[1], [-1], [1], [-1], [1]]
    start = np.concatenate([[0], np.cumsum(counts)])
    position = np.repeat(centre, counts, axis=0) + rng.normal(size=(start[-1], 3)) * 0.1
    position[start[3]:start[4]] = centre[3] + [0.0, 0.05, 0.07]   # patch 3: one quarter
    gain = rng.random(start[-1])
    gain[start[4]:start[5]] = 0.0                                  # patch 4: dark
    pieces = Pieces(start, position, rng.normal(size=(start[-1], 3)), rng.random(start[-1]), gain, 0.3)
    out = quartered(pieces, centre, normal)
    rows = []
    for e in range(5):
        a, b = (np.argmax(np.abs(normal[e])) + 1) % 3, (np.argmax(np.abs(normal[e])) + 2) % 3
        mine = np.arange(start[e], start[e + 1])
        quarter = 2 * (position[mine, a] > centre[e, a]) + (position[mine, b] > centre[e, b])
        for q in range(4):
            s = mine[quarter == q]
            if len(s):
                w, power = pieces.area[s], pieces.area[s] * gain[s]
                at = power @ position[s] / power.sum() if power.sum() > 0 else w @ position[s] / w.sum()
                n = w @ pieces.normal[s]
                rows.append((e, w.sum(), power.sum() / w.sum(), at, n / np.linalg.norm(n)))
    per_patch = np.bincount([r[0] for r in rows], minlength=5)
    assert out.start.tolist() == np.concatenate([[0], np.cumsum(per_patch)]).tolist()
    assert np.diff(out.start)[1] == 0 and np.diff(out.start)[3] == 1
    np.testing.assert_allclose(out.area, [r[1] for r in rows], rtol=1e-12)
    np.testing.assert_allclose(out.gain, [r[2] for r in rows], rtol=1e-12, atol=0)
    np.testing.assert_allclose(out.position, [r[3] for r in rows], rtol=1e-12)
    np.testing.assert_allclose(out.normal, [r[4] for r in rows], rtol=1e-12)
    assert out.near == 0.3


def test_the_gather_sums_every_patch_at_every_probe_with_its_shadow():
    """The compiled gather against the sum written out in numpy: patches of random places, facings, areas
    and colours (one colour black), shadowed per patch and probe, over more probes than one block holds."""
    from viewer.neural.direct import NEAR_FIELD, SH_BLOCK

    rng = np.random.default_rng(3)
    patches, probes = 37, 2 * SH_BLOCK + 29
    points, source = rng.random((probes, 3)), rng.random((patches, 3))
    normal = rng.normal(size=(patches, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    area, radiance = rng.random(patches) * 0.01, rng.random((patches, 3))
    radiance[:, 1] = 0.0
    visible = (rng.random((probes, patches)) > 0.3).astype(np.float64)
    offset = source[None] - points[:, None]                                   # (P, E, 3)
    r2 = np.sum(offset * offset, axis=2)
    direction = offset / np.sqrt(r2)[..., None]
    weight = np.maximum(-np.sum(direction * normal[None], axis=2), 0.0) * area / (r2 + area * NEAR_FIELD)
    bases = sh.basis(direction.reshape(-1, 3)).reshape(probes, patches, sh.SH_COUNT)
    expected = np.einsum("pe,pek,ec->pkc", weight * visible, bases, radiance)
    got = encoding.emitter_sh((source, normal, area, radiance), points, visible)
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-6 * np.abs(expected).max())
    assert np.all(got[:, :, 1] == 0.0)
    unshadowed = np.einsum("pe,pek,ec->pkc", weight, bases, radiance)
    np.testing.assert_allclose(encoding.emitter_sh((source, normal, area, radiance), points), unshadowed,
                               rtol=1e-4, atol=1e-6 * np.abs(unshadowed).max())
