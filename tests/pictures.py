"""Helpers for tests that look at pictures: mean colours of image regions, the Cornell box's walls, and
which world point a pixel shows. Image regions are fractions of the image: (top, bottom, left, right)."""

from __future__ import annotations

import numpy as np

CEILING = (0.03, 0.09, 0.35, 0.65)
RED_WALL = (0.3, 0.7, 0.15, 0.22)
GREEN_WALL = (0.3, 0.7, 0.78, 0.85)


def region(image: np.ndarray, box) -> np.ndarray:
    """Mean sRGB colour (0..255) of a region given as fractions (top, bottom, left, right)."""
    h, w = image.shape[:2]
    top, bottom, left, right = box
    return image[int(top * h):int(bottom * h), int(left * w):int(right * w), :3].reshape(-1, 3).mean(axis=0)


def assert_cornell_box(image: np.ndarray) -> None:
    red, green = region(image, RED_WALL), region(image, GREEN_WALL)
    assert red[0] > 60 and red[0] > 2.5 * red[1], f"left wall not red: {red}"
    assert green[1] > 40 and green[1] > 1.5 * green[0], f"right wall not green: {green}"


def pixel_on_plane(camera, size, pixel, point, normal):
    """The world point seen through the centre of pixel (column, row from the top), on a plane."""
    from viewer.gpu.camera import perspective, view_matrix

    width, height = size
    inverse = np.linalg.inv(perspective(camera.fov, width / height, 0.1, 10.0) @ view_matrix(camera))
    ndc = np.array([(pixel[0] + 0.5) / width * 2 - 1, 1 - (pixel[1] + 0.5) / height * 2, 1.0, 1.0])
    far = inverse @ ndc
    origin = np.asarray(camera.origin, np.float64)
    direction = far[:3] / far[3] - origin
    t = np.dot(np.asarray(point) - origin, normal) / np.dot(direction, normal)
    return origin + t * direction
