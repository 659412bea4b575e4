"""What an edit does to the baked surfaces: a colour edit keeps the geometry's work and draws what a fresh
renderer draws, a moved lamp traces, filters and weighs again only what the move changed, a new scene's
rays start before its first probes, and a colour edit's gather waits for the probes being computed."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from surfaces import background_renderer, render, wait_for_weights

from viewer.gpu.offscreen import OffscreenRenderer
from viewer.gpu.renderer import RenderSettings


def test_a_colour_edit_keeps_the_geometry_work_and_draws_what_a_fresh_renderer_draws(gl_context, cornell,
                                                                                   cornell_probes, monkeypatch):
    """An edit of colours (a wall's albedo, the lamp's colour and intensity) keeps the triangles: the
    renderer keeps the texel weights and final-gather rays and the shadow maps (seconds of work on a new
    geometry) and draws what a renderer given the edited scene from the start draws: exactly after an
    albedo edit, and within the half floats' rounding (a part in 2000) after the lamp's, whose light the
    renderer scales instead of baking it again (the lamps light the Cornell box alone). A lamp moved is
    new geometry: everything is made again."""
    from viewer.gpu import indirect_bake, renderer as renderer_module

    groups = {name: cornell.group_index(name) for name in cornell.groups}
    emitter = next(name for name, k in groups.items() if cornell.emission[cornell.face_group == k].max() > 0)
    wall = max((n for n in groups if n != emitter), key=lambda n: cornell.face_areas[cornell.face_group == groups[n]].sum())
    lamp = cornell.face_group == groups[emitter]
    edits = [cornell.with_albedo(wall, (0.9, 0.3, 0.2))]
    emission = cornell.emission.copy()
    emission[lamp] *= np.array([0.4, 0.8, 1.6])
    edits.append(replace(cornell, emission=emission))

    fresh = [render(gl_context, edited, cornell_probes, (64, 64))["final"] for edited in edits]
    made, shadows = [], []
    original = indirect_bake.BakedIndirectLight.weights_of
    monkeypatch.setattr(indirect_bake.BakedIndirectLight, "weights_of",
                        lambda self, probes: made.append(probes.resolution) or original(self, probes))
    bakes = []
    original_bake = renderer_module.BakedDirectLight.bake
    monkeypatch.setattr(renderer_module.BakedDirectLight, "bake",
                        lambda self, *args: bakes.append(1) or original_bake(self, *args))
    original_shadows = renderer_module.EmitterShadows.render
    monkeypatch.setattr(renderer_module.EmitterShadows, "render",
                        lambda self, *args: shadows.append(1) or original_shadows(self, *args))
    offscreen = OffscreenRenderer((64, 64), samples=0, ctx=gl_context)
    try:
        renderer = offscreen.renderer
        renderer.set_scene(cornell)
        renderer.set_probes(cornell_probes)
        first = offscreen.render_hdr(view="final")
        for edited, expected, rtol in zip(edits, fresh, (1e-4, 1e-3)):
            bakes.clear()
            renderer.set_scene(edited)
            renderer.set_probes(cornell_probes)
            image = offscreen.render_hdr(view="final")
            assert not np.allclose(image, first, rtol=1e-2)
            assert (made, shadows) == ([24], [1]), "the geometry's work was kept"
            assert not bakes, "no bake: the lightmap holds irradiance, and the lamp's is scaled"
            np.testing.assert_allclose(image, expected, rtol=rtol, atol=1e-6)
            first = image
        moved = lamp_moved(cornell)
        renderer.set_scene(moved)
        renderer.set_probes(cornell_probes)
        image = offscreen.render_hdr(view="final")
        assert (made, shadows) == ([24, 24], [1, 1])
        monkeypatch.undo()
        np.testing.assert_allclose(image, render(gl_context, moved, cornell_probes, (64, 64))["final"],
                                   rtol=1e-4, atol=1e-6)
    finally:
        offscreen.release()


def lamp_moved(scene, by=-0.05):
    """The scene with its emitting faces moved along z."""
    lamp = np.unique(scene.faces[scene.emission.max(axis=1) > 0])
    vertices = scene.vertices.copy()
    vertices[lamp, 2] += by
    return replace(scene, vertices=vertices)


def test_a_moved_lamp_retraces_only_what_changed_and_shows_the_probes_meanwhile(gl_context, cornell, cornell_probes,
                                                                                 monkeypatch):
    """The viewer drags a lamp: the same faces elsewhere, the same lightmap layout. While the worker
    traces again the gather rays the move can change, the frames read the probes per fragment (the old
    geometry's rays would leave the ceiling the lamp covered dark), and once the new weights land the
    image is the one a renderer given the moved scene draws, from the same rays a full trace gives."""
    moved = lamp_moved(cornell)
    expected = render(gl_context, moved, cornell_probes, (64, 64), ("indirect",))["indirect"]
    offscreen = background_renderer(gl_context, cornell, cornell_probes, (64, 64))
    try:
        renderer = offscreen.renderer
        offscreen.render_hdr(view="indirect")
        wait_for_weights(renderer)
        full, incremental = count_traces(monkeypatch)
        renderer.set_scene(moved)
        renderer.set_probes(cornell_probes)
        meanwhile = offscreen.render_hdr(view="indirect")
        assert renderer.baking and renderer._indirect.stale
        exact = render(gl_context, moved, cornell_probes, (64, 64), ("indirect",),
                       RenderSettings(baked=False))["indirect"]
        np.testing.assert_allclose(meanwhile, exact, rtol=1e-4, atol=1e-6)   # the probes per fragment
        wait_for_weights(renderer)
        np.testing.assert_allclose(offscreen.render_hdr(view="indirect"), expected, rtol=1e-3, atol=1e-5)
        assert (full, incremental) == ([], [1])
        monkeypatch.undo()
        fresh = OffscreenRenderer((64, 64), samples=0, ctx=gl_context)
        try:   # only the rays the move can change were traced again, and they are all a new trace gives
            fresh.renderer.set_scene(moved)
            fresh.renderer.set_probes(cornell_probes)
            fresh.render_hdr(view="indirect")
            ours, theirs = renderer._indirect._gather, fresh.renderer._indirect._gather
            np.testing.assert_array_equal(ours[0].hits, theirs[0].hits)
            # and only the samples near the lamp were filtered again, to the rows filtering all of them gives
            assert 0 < ours[1].filtered < 0.5 * theirs[1].filtered
            np.testing.assert_array_equal(ours[1].near, theirs[1].near)
            np.testing.assert_array_equal(ours[1].tent, theirs[1].tent)
            # the probe weights too: weighed again near the lamp alone, the same as weighing every sample
            kept = next(iter(renderer._indirect._weighed.values()))[1]
            assert 0 < kept.weighed < 0.5 * len(kept.points)
            np.testing.assert_array_equal(renderer._indirect._bake.weights, fresh.renderer._indirect._bake.weights)
        finally:
            fresh.release()
    finally:
        offscreen.release()


def count_traces(monkeypatch) -> tuple[list, list]:
    """Lists that get an entry each time a geometry's final-gather rays are all traced (GatherRays.of), and
    each time only those a move can change are (GatherRays.after_moving)."""
    from viewer.gpu.final_gather import GatherRays

    incremental = []
    original = GatherRays.after_moving
    monkeypatch.setattr(GatherRays, "after_moving",
                        lambda self, *a, **k: incremental.append(1) or original(self, *a, **k))
    return count_full_traces(monkeypatch), incremental


def count_full_traces(monkeypatch) -> list:
    """A list that gets an entry each time a geometry's final-gather rays are all traced (GatherRays.of)."""
    from viewer.gpu.final_gather import GatherRays

    traced = []
    original = GatherRays.of
    monkeypatch.setattr(GatherRays, "of", staticmethod(lambda *a, **k: traced.append(1) or original(*a, **k)))
    return traced


def test_a_new_scenes_rays_are_traced_before_its_first_probes(gl_context, cornell, cornell_probes, monkeypatch):
    """In the viewer the final gather's rays of a new scene are traced on the worker from its first frame,
    while the GI source computes the probes (they need none), and once: the weights that follow the
    probes reuse them."""
    import time

    traced = count_full_traces(monkeypatch)
    offscreen = OffscreenRenderer((64, 64), samples=0, ctx=gl_context)
    try:
        renderer = offscreen.renderer
        renderer.background_bake = True
        renderer.set_scene(cornell)
        offscreen.render_hdr(view="final")          # no probes yet: direct light only
        deadline = time.monotonic() + 600
        while not traced or renderer._indirect._made is None:
            assert time.monotonic() < deadline
            time.sleep(0.02)
        renderer.set_probes(cornell_probes)
        offscreen.render_hdr(view="indirect")
        wait_for_weights(renderer)
        assert traced == [1]
    finally:
        offscreen.release()


def test_after_a_colour_edit_the_indirect_light_waits_for_the_probes_the_gi_source_is_computing(
        gl_context, cornell, cornell_probes, monkeypatch):
    """A colour edit re-gathers the indirect lightmap once, with the probes computed for it, not first with
    the old ones as well (`probes_pending`, set by the viewer while its GI source works); without pending
    probes, or past AWAIT_PROBES, it is gathered at once."""

    from viewer.gpu import lightmaps
    from viewer.gpu.indirect_bake import BakedIndirectLight

    updates = []
    original = BakedIndirectLight.update
    monkeypatch.setattr(BakedIndirectLight, "update", lambda self, probes: updates.append(probes) or original(self, probes))
    offscreen = OffscreenRenderer((32, 32), samples=0, ctx=gl_context)
    try:
        renderer = offscreen.renderer
        renderer.set_scene(cornell)
        renderer.set_probes(cornell_probes)
        offscreen.render_hdr(view="final")
        assert len(updates) == 1
        greener = replace(cornell, albedo=cornell.albedo * np.array([0.8, 1.0, 0.8]))
        renderer.probes_pending = True
        renderer.set_scene(greener)
        offscreen.render_hdr(view="final")
        assert len(updates) == 1                      # the last gather shows until the new probes come
        renderer.set_probes(cornell_probes)
        offscreen.render_hdr(view="final")
        assert len(updates) == 2
        renderer.set_scene(cornell)
        monkeypatch.setattr(lightmaps, "AWAIT_PROBES", 0.0)
        renderer._stale_indirect(awaiting=True)
        offscreen.render_hdr(view="final")
        assert len(updates) == 3                      # waited long enough
        renderer.probes_pending = False
        renderer.set_scene(greener)
        offscreen.render_hdr(view="final")
        assert len(updates) == 4                      # no probes coming: gathered at once
    finally:
        offscreen.release()


def test_a_moved_box_retraces_only_the_rays_it_can_change(gl_context, cornell, cornell_probes, monkeypatch):
    """A box dragged across the room is a third of the Cornell box's faces but only 12 of them: its gather
    rays are traced again where the move can change them alone, and they are the rays a full trace of
    the moved scene gives, the image the one a fresh renderer draws."""
    matrix = np.eye(4)
    matrix[0, 3] = 0.08
    moved = cornell.transformed_group("small-box", matrix)
    expected = render(gl_context, moved, cornell_probes, (64, 64), ("indirect",))["indirect"]
    offscreen = background_renderer(gl_context, cornell, cornell_probes, (64, 64))
    try:
        renderer = offscreen.renderer
        offscreen.render_hdr(view="indirect")
        wait_for_weights(renderer)
        full, incremental = count_traces(monkeypatch)
        renderer.set_scene(moved)
        renderer.set_probes(cornell_probes)
        offscreen.render_hdr(view="indirect")
        wait_for_weights(renderer)
        np.testing.assert_allclose(offscreen.render_hdr(view="indirect"), expected, rtol=1e-3, atol=1e-5)
        assert (full, incremental) == ([], [1])
        monkeypatch.undo()
        fresh = OffscreenRenderer((64, 64), samples=0, ctx=gl_context)
        try:
            fresh.renderer.set_scene(moved)
            fresh.renderer.set_probes(cornell_probes)
            fresh.render_hdr(view="indirect")
            np.testing.assert_array_equal(renderer._indirect._gather[0].hits, fresh.renderer._indirect._gather[0].hits)
        finally:
            fresh.release()
    finally:
        offscreen.release()
