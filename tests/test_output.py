"""Files written for a user (viewer/output.py): whole or not at all, exactly where the user said."""

from __future__ import annotations

import os

import numpy as np
import pytest

from viewer.output import replacing


def test_the_file_is_written_exactly_where_asked(tmp_path):
    target = tmp_path / "grid.bin"
    with replacing(target) as out:
        np.save(out, np.arange(4.0))
    np.testing.assert_array_equal(np.load(target), np.arange(4.0))
    assert [p.name for p in tmp_path.iterdir()] == ["grid.bin"]


def test_a_failed_write_leaves_the_previous_file_and_nothing_else(tmp_path):
    """A write that fails halfway (a full disk, Ctrl-C) does not truncate the file the user had."""
    target = tmp_path / "grid.npz"
    target.write_bytes(b"the previous grid")
    with pytest.raises(OSError, match="No space"):
        with replacing(target) as out:
            out.write(b"half a new gr")
            raise OSError(28, "No space left on device")
    assert target.read_bytes() == b"the previous grid"
    assert [p.name for p in tmp_path.iterdir()] == ["grid.npz"]


def test_a_new_file_gets_the_permissions_of_any_new_file(tmp_path):
    old = os.umask(0o022)
    try:
        with replacing(tmp_path / "picture.png") as out:
            out.write(b"png")
    finally:
        os.umask(old)
    assert (tmp_path / "picture.png").stat().st_mode & 0o777 == 0o644
