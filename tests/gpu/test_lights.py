"""Light samples on the area emitters (numpy, no GL): they must carry the emitters' whole power."""

from __future__ import annotations

import numpy as np

from viewer.gpu.lights import emitter_samples
from viewer.scene import load


def test_samples_lie_on_the_lamp_and_carry_its_area_and_power():
    scene = load("cornell")
    lamp = np.any(scene.emission > 0, axis=1)
    area = scene.face_areas[lamp].sum()
    samples = emitter_samples(scene, 32)
    assert samples.count == 32
    np.testing.assert_allclose(samples.area.sum(), area, rtol=1e-9)
    np.testing.assert_allclose(samples.power.sum(axis=0), (scene.emission[lamp] * scene.face_areas[lamp, None]).sum(0),
                               rtol=1e-9)
    lo, hi = scene.vertices[scene.faces[lamp]].reshape(-1, 3).min(0), scene.vertices[scene.faces[lamp]].reshape(-1, 3).max(0)
    assert np.all(samples.position >= lo - 1e-9) and np.all(samples.position <= hi + 1e-9)
    np.testing.assert_allclose(samples.normal, np.tile([0.0, -1.0, 0.0], (32, 1)), atol=1e-12)  # facing down
    frames = np.stack([samples.tangent, samples.bitangent, samples.normal], axis=1)
    np.testing.assert_allclose(frames @ frames.transpose(0, 2, 1), np.tile(np.eye(3), (32, 1, 1)), atol=1e-12)


def test_samples_cover_the_lamp_evenly():
    """Stratified: every quarter of the lamp gets a quarter of the samples."""
    scene = load("cornell")
    samples = emitter_samples(scene, 64)
    centre = np.median(samples.position, axis=0)
    quadrant = (samples.position[:, 0] > centre[0]).astype(int) * 2 + (samples.position[:, 2] > centre[2])
    counts = np.bincount(quadrant, minlength=4)
    assert counts.min() >= 12, counts


def test_a_scene_without_emitters_has_no_samples():
    scene = load("cornell")
    dark = scene.with_emission("light", [0.0, 0.0, 0.0])
    assert emitter_samples(dark, 16).count == 0


def test_the_baked_sunlight_is_where_rays_reach_the_sun_in_a_room_lit_by_a_window(gl_context):
    """The sun's shadow map against rays cast to the sun from every lightmap texel that faces it, in a
    generated room whose sun comes in by a window (its lamps off) and grazes the back wall: inside the
    room (the faces' front sides) the map let three times the sunlight in, a lit line down the corner
    where that wall meets another; outside (the back sides, in the open sun) it must stay lit."""
    from dataclasses import replace

    from viewer.bench.stability.sun import sunny_room
    from viewer.gpu.offscreen import OffscreenRenderer
    from viewer.gpu.render_settings import RenderSettings
    from viewer.rays.cast import TriangleCaster

    room, _ = sunny_room(3)
    room = replace(room, emission=np.zeros_like(room.emission))
    offscreen = OffscreenRenderer((32, 32), RenderSettings(), samples=0, ctx=gl_context)
    try:
        offscreen.renderer.set_scene(room)
        offscreen.render_hdr(view="direct")
        lightmap, scene = offscreen.renderer._baked, offscreen.renderer._draw_scene
        height, width = lightmap.covered.shape
        texels = np.frombuffer(lightmap.texture.read(), np.float16).reshape(height, 2 * width, 4)
        rows, columns = np.nonzero(lightmap.covered)
        points, normals = lightmap.texel_points.astype(np.float64), lightmap.texel_normals.astype(np.float64)
        caster = TriangleCaster(scene)
        sun = scene.sun.direction / np.linalg.norm(scene.sun.direction)
        for side, sign, shift in (("inside", 1.0, 0), ("outside", -1.0, width)):
            cosine = sign * normals @ sun
            facing = np.flatnonzero(cosine > 0.05)
            seen = ~caster.blocked(points[facing] + 1e-5 * sign * normals[facing], np.tile(sun, (len(facing), 1)),
                                   np.full(len(facing), 1e3))
            baked = texels[rows[facing], columns[facing] + shift, :3].astype(np.float64).mean(axis=1)
            share = baked / (np.mean(scene.sun.irradiance) * cosine[facing])
            assert abs(share.mean() - seen.mean()) < 0.1 * seen.mean() + 0.002, side
            assert np.mean(np.abs(share - seen) > 0.5) < 0.001, side       # texels at shadow edges
    finally:
        offscreen.release()
