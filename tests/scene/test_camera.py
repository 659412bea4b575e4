"""The camera a scene opens with when its file has none (viewer/scene/camera.py)."""

import numpy as np
import pytest

from viewer.scene.camera import framing_camera


@pytest.mark.parametrize("aspect", [16 / 9, 1.0, 0.5, 2.4])
@pytest.mark.parametrize("box", [([-3.0, 0.0, -1.0], [5.0, 2.0, 1.0]), ([-1.0, 0.0, -1.0], [1.0, 2.0, 1.0]),
                                 ([0.0, 0.0, 0.0], [0.2, 3.0, 0.2])])
def test_framing_camera_fills_the_picture_with_the_whole_box(aspect, box):
    """Every corner of the box is inside the picture, and the box reaches the margin on the side that binds
    (its width or its height): a wide picture does not leave a room at a third of its width."""
    from viewer.gpu.camera import view_projection
    from viewer.scene.camera import FRAMING_MARGIN

    lo, hi = np.array(box[0]), np.array(box[1])
    camera = framing_camera(lo, hi, aspect=aspect)
    corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    clip = corners @ view_projection(camera, aspect, lo, hi).T
    assert np.all(clip[:, 3] > 0)
    ndc = clip[:, :2] / clip[:, 3:]
    assert np.abs(ndc).max() == pytest.approx(1.0 / FRAMING_MARGIN, rel=1e-6)
