"""The gallery's comparison numbers on images whose answer is known by hand."""

import numpy as np
import pytest

from viewer.bench.gallery import mean_relative_difference, psnr, side_by_side, to_srgb8


def test_srgb_encoding_clamps_and_follows_the_standard_curve():
    """0 -> 0, 1 and above -> 255, linear 0.5 -> 188 (sRGB 0.7354), one stop of exposure doubles."""
    radiance = np.array([[[0.0, 0.5, 1.0], [4.0, 0.25, -1.0]]], np.float32)
    assert to_srgb8(radiance).tolist() == [[[0, 188, 255], [255, 137, 0]]]
    assert to_srgb8(radiance, exposure=1.0)[0, 1, 1] == 188


def test_psnr_of_a_one_level_error_is_48_db():
    """MSE 1 on an 8-bit scale: 10 log10(255^2) = 48.13 dB; identical images: infinite."""
    image = np.full((8, 8, 3), 100, np.uint8)
    assert psnr(image + 1, image) == pytest.approx(48.13, abs=0.01)
    assert psnr(image, image) == float("inf")


def test_mean_relative_difference_of_a_ten_percent_brighter_image():
    truth = np.random.default_rng(0).uniform(0.1, 2.0, (16, 16, 3)).astype(np.float32)
    assert mean_relative_difference(1.1 * truth, truth) == pytest.approx(0.1, rel=1e-5)


def test_side_by_side_puts_ours_left_and_the_reference_right():
    left, right = np.zeros((4, 5, 3), np.uint8), np.full((4, 5, 3), 9, np.uint8)
    both = side_by_side(left, right, gap=2)
    assert both.shape == (4, 12, 3) and both[:, :5].max() == 0 and both[:, 7:].min() == 9
