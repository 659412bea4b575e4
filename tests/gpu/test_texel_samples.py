"""The compiled loops that spread the samples' light onto the lightmap's texels (viewer/gpu/texel_samples.py):
the fused pass gives what its parts give."""

import numpy as np

from viewer.gpu.texel_samples import gather_reflected, gather_texels


def test_the_fused_pass_gives_what_its_parts_give():
    """`gather_reflected` is albedo x `gather_texels` + reflected, and leaves the other pixels alone."""
    rng = np.random.default_rng(4)
    samples, pixels_count = 500, 3000
    values = rng.uniform(0, 5, (samples, 3)).astype(np.float32)
    rows = rng.integers(0, samples, (2000, 4))
    weights = rng.uniform(0, 1, (2000, 4)).astype(np.float32)
    weights[rng.random((2000, 4)) < 0.3] = 0.0
    pixels = rng.choice(pixels_count, 2000, replace=False)
    albedo = rng.uniform(0, 1, (pixels_count, 3)).astype(np.float32)
    reflected = rng.uniform(0, 1, (pixels_count, 3)).astype(np.float32)
    image = np.zeros((pixels_count, 3), np.float32)
    gather_texels(values, rows, weights, pixels, image)
    fused = np.zeros((pixels_count, 3), np.float32)
    gather_reflected(values, rows, weights, pixels, albedo, reflected, fused)
    np.testing.assert_allclose(fused[pixels], albedo[pixels] * image[pixels] + reflected[pixels], rtol=1e-6)
    assert not fused[np.setdiff1d(np.arange(pixels_count), pixels)].any()   # the others untouched
