"""Half floats widened in compiled code (viewer/gpu/half_floats.py) are numpy's, bit for bit."""

import numpy as np

from viewer.gpu.half_floats import widened


def test_every_half_float_widens_as_numpy_widens_it():
    """All 65,536 bit patterns (zeros of both signs, subnormals, infinities, NaNs with their payloads), in
    the first three of four channels, in rows read back from a texture."""
    bits = np.arange(1 << 16, dtype=np.uint16)
    halves = np.stack([bits, bits[::-1], np.roll(bits, 7), bits], axis=1).view(np.float16)
    ours = widened(halves, 3)
    assert ours.shape == (1 << 16, 3) and ours.dtype == np.float32
    assert np.array_equal(ours.view(np.uint32), halves[:, :3].astype(np.float32).view(np.uint32))
