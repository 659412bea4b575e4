"""What the encoder's tests (tests/neural/test_encoder*.py) share: a scene's voxels, occluders and
`encoding.encode`'s reference, their comparison to round-off, a group moved, a ceiling lamp of one's own."""

import numpy as np

from scenes import ceiling_lamp
from viewer.neural import encoding
from viewer.rays.voxels import voxelize
from viewer.scene import Scene

VOXELS = 16


def assert_same_encoding(ours: encoding.Encoding, reference: encoding.Encoding) -> None:
    """Equal to float32 round-off: the inputs are in units of each pass's scale, so an absolute 1e-5 is
    1e-5 of the field's scale (and 1e-5 relative next to a lamp, where they reach tens)."""
    assert ours.inputs.shape == reference.inputs.shape
    np.testing.assert_allclose(ours.scale, reference.scale, rtol=1e-5, atol=1e-12)
    np.testing.assert_allclose(ours.inputs, reference.inputs, rtol=1e-5, atol=1e-5)


def encoded(scene: Scene, resolution: int = 16):
    """(voxels, occluders, `encoding.encode`'s reference) of `scene` over its bounds."""
    voxels = voxelize(scene, VOXELS)
    blockers = encoding.occluders(scene, voxels)
    lo, hi = scene.bounds
    return voxels, blockers, encoding.encode(voxels, scene.sun, lo, hi, resolution, blockers)


def moved(scene: Scene, group: str, offset) -> Scene:
    matrix = np.eye(4)
    matrix[:3, 3] = offset
    return scene.transformed_group(group, matrix)


def lamp(name: str, x: float, z: float, radiance, half_size: float = 0.1) -> Scene:
    shape = ceiling_lamp(half_size=half_size)
    return Scene(name, shape.vertices + (x, 0.0, z), shape.faces, 0.0, radiance, 0, (name,))
