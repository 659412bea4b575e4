"""The passes of an indirect lightmap update (viewer/gpu/lightmap_update.py):
the fused pass gives what its parts give."""

import numpy as np

from viewer.gpu.final_gather import ESCAPED, GatherRays
from viewer.gpu.lightmap_update import Landing, Reached, gather_reflected, gather_texels


def test_the_fused_pass_gives_what_its_parts_give():
    """`gather_reflected` is albedo x `gather_texels` + reflected, pixel by pixel of the landing ones."""
    rng = np.random.default_rng(4)
    samples, landing = 500, 2000
    values = rng.uniform(0, 5, (samples, 3)).astype(np.float32)
    rows = rng.integers(0, samples, (landing, 4))
    weights = rng.uniform(0, 1, (landing, 4)).astype(np.float32)
    weights[rng.random((landing, 4)) < 0.3] = 0.0
    albedo = rng.uniform(0, 1, (landing, 3)).astype(np.float32)
    reflected = rng.uniform(0, 1, (landing, 3)).astype(np.float32)
    image = np.zeros((landing, 3), np.float32)
    gather_texels(values, rows, weights, np.arange(landing), image, np.arange(landing))
    fused = np.empty((landing, 3), np.float32)
    gather_reflected(values, rows, weights, albedo, reflected, fused)
    np.testing.assert_allclose(fused, albedo * image + reflected, rtol=1e-6)


def test_the_rays_land_on_their_pixels_rows():
    """`GatherRays.landing` numbers the distinct pixels hit, in image order; each ray's row names its pixel,
    a ray that escaped stays escaped. `Landing.of` gives each landing pixel the rows and weights its
    texel interpolates, its face and texel, and nothing for a pixel no texel covers."""
    rng = np.random.default_rng(5)
    size = 400
    hits = rng.integers(0, size, (60, 8)).astype(np.int32)
    hits[rng.random(hits.shape) < 0.4] = ESCAPED
    pixels, rows = GatherRays(hits).landing
    np.testing.assert_array_equal(pixels, np.unique(hits[hits >= 0]))
    np.testing.assert_array_equal(pixels[rows[hits >= 0]], hits[hits >= 0])
    assert (rows[hits < 0] == ESCAPED).all()

    covered = rng.choice(size, 300, replace=False)       # front texels, then back: 150 texels a side
    texel_faces = rng.integers(0, 20, 150)
    covered_faces = np.concatenate([texel_faces, texel_faces])
    texel_rows = rng.integers(0, 99, (300, 4)), rng.uniform(0, 1, (300, 4)).astype(np.float32)
    landing = Landing.of(pixels, covered, texel_rows, texel_faces, size)
    where = {p: i for i, p in enumerate(covered)}
    for k, p in enumerate(pixels):
        if p in where:
            i = where[p]
            np.testing.assert_array_equal(landing.rows[k], texel_rows[0][i])
            np.testing.assert_array_equal(landing.weights[k], texel_rows[1][i])
            assert landing.faces[k] == covered_faces[i] and landing.texels[k] == i % 150
        else:
            assert not landing.weights[k].any() and landing.faces[k] == -1 and landing.texels[k] == -1
    np.testing.assert_array_equal(landing.samples, np.unique(landing.rows[landing.weights > 0]))


def test_the_texels_no_light_reaches_are_left_at_the_zero_they_would_get():
    """Filtering and spreading only the samples and texels that `Reached` names gives the image that
    filtering and spreading them all gives: the others read only records none of whose rays landed."""
    rng = np.random.default_rng(6)
    records, samples, texels = 300, 400, 1500
    landed = np.flatnonzero(rng.random(records) < 0.5)
    irradiance = np.zeros((records, 3), np.float32)
    irradiance[landed] = rng.uniform(0.1, 2.0, (len(landed), 3))     # what `GatherRays.irradiance` gives
    near = rng.integers(0, records, (samples, 16))
    near[:120] = rng.choice(np.setdiff1d(np.arange(records), landed), (120, 16))   # in the dark
    tent = rng.uniform(0, 1, (samples, 16)).astype(np.float32)
    tent[rng.random(tent.shape) < 0.3] = 0.0
    pixels = rng.choice(3000, texels, replace=False)
    rows = rng.integers(120, samples, (texels, 4))
    rows[:500] = rng.integers(0, 120, (500, 4))                       # texels that read dark samples alone
    rows[500:520, 0] = rng.integers(0, 120, 20)                       # and some that read both
    weights = rng.uniform(0, 1, (texels, 4)).astype(np.float32)

    values = rng.uniform(0, 1, (samples, 3)).astype(np.float32)       # the probes' light, before the filter
    whole = np.zeros((3000, 3), np.float32)
    everything = values.copy()
    gather_texels(irradiance, near, tent, np.arange(samples), everything, np.arange(samples))
    gather_texels(everything, rows, weights, pixels, whole, np.arange(texels))

    reached = Reached.of(landed, near, tent, rows, weights)
    assert 0 < len(reached.texels) < texels and len(reached.samples) < samples
    part = np.zeros((3000, 3), np.float32)
    gather_texels(irradiance, near, tent, np.arange(samples), values, reached.samples)
    gather_texels(values, rows, weights, pixels, part, reached.texels)
    np.testing.assert_array_equal(part, whole)
