"""A frame right after an edit gives the GI source's work in flight up to the time the last frame took
(`Session.update`'s `frame_seconds`), so that it shows the edit's light instead of the old one. The
relight is held on an event here, so that what a frame shows does not depend on the worker's speed."""

from __future__ import annotations

import threading

import pytest

from viewer.bench.headless import HeadlessViewer
from viewer.physical.gi import GISettings, PhysicalGI
from viewer.ui import session as session_module

SMALL = GISettings(voxels=12, probes=6)


@pytest.fixture()
def viewer():
    viewer = HeadlessViewer("compute", SMALL, size=(96, 64))
    if viewer.gi.source != "compute":
        pytest.skip(viewer.gi.unavailable["compute"])
    viewer.settle()
    yield viewer
    viewer.release()


@pytest.fixture()
def held(monkeypatch):
    """The relight waits for this event (set: it runs at once)."""
    event, relight = threading.Event(), PhysicalGI.relight

    def waiting(self, *args, **kwargs):
        event.wait()
        return relight(self, *args, **kwargs)

    monkeypatch.setattr(PhysicalGI, "relight", waiting)
    monkeypatch.setattr(session_module, "EDIT_WAIT", 600.0)
    return event


def test_the_frame_after_a_colour_edit_waits_for_its_relight(viewer, held):
    viewer.frame_seconds = 600.0   # a frame as slow as a million triangles on a software GL, and more
    before = viewer.session.probes_version
    viewer.session.edits.set_light(colour=(1.0, 0.8, 0.6))
    threading.Timer(0.2, held.set).start()   # released while the frame waits
    viewer.frame()
    assert viewer.session.probes_version != before and not viewer.gi.busy


def test_without_a_measured_frame_the_frame_after_an_edit_shows_the_old_light(viewer, held):
    viewer.frame_seconds = 0.0   # no frame drawn yet: nothing to weigh the wait against
    before = viewer.session.probes_version
    viewer.session.edits.set_light(colour=(0.7, 0.85, 1.0))
    viewer.frame()
    assert viewer.session.probes_version == before and viewer.gi.busy
    held.set()
    viewer.settle()
    assert viewer.session.probes_version != before


def test_a_drag_is_not_waited_for(viewer, held, monkeypatch):
    """A dragged lamp's traces can take longer than a frame: the frame after it is drawn at once."""
    viewer.frame_seconds = 600.0
    waits = []
    monkeypatch.setattr(viewer.gi, "wait", waits.append)
    viewer.session.edits.set_light(offset=(0.05, 0.0, 0.0))
    viewer.frame()
    assert waits == []
    held.set()
    viewer.settle()
