"""The final gather's records and their tent filter (viewer/gpu/texel_samples.py) on a finely cut mesh:
the samples of one-sample tiles read the nearest records that face their way, their rays half cast."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from viewer.gpu import texel_samples
from viewer.gpu.compute_relight import solve_probes
from viewer.gpu.final_gather import _all_backs, paired_rays, scout_rays
from viewer.gpu.offscreen import OffscreenRenderer
from viewer.physical.gi import GISettings
from viewer.scene import load


@pytest.fixture(scope="module")
def cut_box(gl_context):
    """The Cornell box with its large box cut into 12,000 triangles, most narrower than two texels, set
    in a renderer with its probes: (the renderer's indirect lightmap, its direct lightmap, the probes)."""
    from viewer.bench.scans import refine

    cornell = load("cornell")
    box = cornell.face_group == cornell.group_index("large-box")
    vertices, cut = refine(cornell.vertices, cornell.faces[box], 12_000)
    keep = np.flatnonzero(~box)
    scene = replace(cornell, vertices=vertices, faces=np.vstack([cornell.faces[keep], cut]),
                    albedo=np.vstack([cornell.albedo[keep], np.tile(cornell.albedo[box][0], (len(cut), 1))]),
                    emission=np.vstack([cornell.emission[keep], np.zeros((len(cut), 3))]),
                    face_group=np.concatenate([cornell.face_group[keep],
                                               np.full(len(cut), cornell.group_index("large-box"))]))
    offscreen = OffscreenRenderer((64, 64), samples=0, ctx=gl_context)
    probes = solve_probes(gl_context, scene, GISettings(), include_emitted=False)
    offscreen.renderer.set_scene(scene)
    offscreen.renderer.set_probes(probes)
    offscreen.render_hdr(view="final")
    yield offscreen.renderer._indirect, offscreen.renderer._baked, probes
    offscreen.release()


def test_a_small_tiles_sample_reads_the_nearest_records_that_face_its_way(cut_box):
    """A sample of a one-sample tile averages, of the records within the largest reach whose normals are
    within SMALL_FACING of its own, the FILTER_MAX nearest, each weighed 1 - distance / reach where it
    lies within half the reach of the sample's plane and not inside a solid: brute force over every
    record agrees. Records that face elsewhere take no place among the FILTER_MAX (on a curved scan
    they are most of the nearest)."""
    indirect, lightmap, _ = cut_box
    samples = indirect._samples
    records, own = indirect._records
    rays, filtered, _ = indirect._gather
    near, tent = filtered.near, filtered.tent
    small = texel_samples.small_tiles(lightmap, samples)
    assert small.sum() > 5000
    points = lightmap.texel_points[samples].astype(np.float64)
    normals = lightmap.texel_normals[samples].astype(np.float64)
    spacing = texel_samples.SAMPLE_STRIDE * lightmap.texel
    bound = max(texel_samples.SMALL_RADIUS, texel_samples.FILTER_RADIUS) * spacing
    reach = texel_samples.SMALL_RADIUS * spacing
    inside = rays.inside(lightmap.covered.shape[1])[:len(records)]
    checked = 0
    for s in np.random.default_rng(3).choice(np.flatnonzero(small), 300, replace=False):
        d = np.linalg.norm(points[records] - points[s], axis=1)
        facing = normals[records] @ normals[s]
        candidates = np.flatnonzero((d < bound) & (facing > texel_samples.SMALL_FACING))
        nearest = candidates[np.argsort(d[candidates], kind="stable")][:texel_samples.FILTER_MAX]
        off = np.abs((points[records[nearest]] - points[s]) @ normals[s])
        weight = np.where((d[nearest] < reach) & (off < 0.5 * reach) & ((nearest == own[s]) | ~inside[nearest]),
                          1.0 - d[nearest] / reach, 0.0)
        row = np.zeros(len(records))
        if weight.sum() > 0:
            row[nearest] = weight / weight.sum()
        else:
            row[own[s]] = 1.0
        ours = np.zeros(len(records))
        np.add.at(ours, near[s], tent[s])
        np.testing.assert_allclose(ours, row, atol=1e-6)
        checked += len(nearest) == texel_samples.FILTER_MAX
    assert checked > 100   # most had more facing records within reach than the filter reads


def test_the_records_of_small_tiles_cast_half_their_rays(cut_box):
    """The gather marks the records of one-sample tiles coarse, both sides, and no other: their repeated
    rays hold their partners' hits (but for the enclosed ones, the box's inside, whose rays all repeat
    their scouts')."""
    indirect, lightmap, _ = cut_box
    records = indirect._records[0]
    rays = indirect._gather[0]
    small = texel_samples.small_tiles(lightmap, indirect._samples[records])
    assert 0 < small.mean() < 1
    np.testing.assert_array_equal(rays.coarse, np.concatenate([small, small]))
    repeated = paired_rays(rays.hits.shape[1])[1]
    enclosed = _all_backs(rays.hits[:, scout_rays(rays.hits.shape[1])], lightmap.covered.shape[1])
    hits = rays.hits[rays.coarse & ~enclosed]
    assert len(hits) > 0.3 * rays.coarse.sum()
    assert (hits[:, repeated] == hits[:, repeated - 1]).all()


def test_a_small_tiles_sample_takes_its_records_probe_weights(cut_box):
    """The probe weights of a one-sample tile's sample are its record's, both sides; every other sample
    has the weights of its own point and normal (`weight_rows`)."""
    from viewer.probes.weights import SurfaceWeights

    indirect, lightmap, probes = cut_box
    records, own = indirect._records
    small = texel_samples.small_tiles(lightmap, indirect._samples)
    weighed, rows = texel_samples.weight_rows(small, (records, own))
    count = len(small)
    assert len(weighed) < 2 * count and len(rows) == 2 * count
    taken = weighed[rows]                              # the sample whose weights each one takes
    front = np.where(small, records[own], np.arange(count))
    np.testing.assert_array_equal(taken, np.concatenate([front, count + front]))
    points, normals, normal_id = indirect._sample_points(lightmap)
    own_weights = SurfaceWeights.of(points, normals[normal_id], probes, indirect._caster)
    np.testing.assert_array_equal(indirect._bake.weights, own_weights.weights[taken])
    everyone = texel_samples.weight_rows(small, None)
    np.testing.assert_array_equal(everyone[0][everyone[1]], np.arange(2 * count))

