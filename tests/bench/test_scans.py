"""The scanned-mesh rooms' builder (viewer/bench/scans.py): the refined mesh is the same surface in the
triangle count asked for, standing on the Cornell box's floor, and the room loads back as written."""

import numpy as np
import trimesh

from viewer.bench import scans
from viewer.scene import load
from viewer.scene.types import Scene


def face_normals(vertices, faces):
    corners = vertices[faces]
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return n, np.linalg.norm(n, axis=1) / 2


def test_refining_keeps_the_surface_its_orientation_and_gives_the_count():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    vertices, faces = scans.refine(sphere.vertices, sphere.faces, 1001)
    assert len(faces) == 1001
    _, area = face_normals(vertices, faces)
    assert abs(area.sum() - sphere.area) < 1e-12 * sphere.area
    # each piece lies in the plane of a face it was cut from, facing the same way (the same unit normal
    # as one of the sphere's faces, none flipped), and the largest face shrank
    normal, _ = face_normals(vertices, faces)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    assert np.all((normal @ sphere.face_normals.T).max(axis=1) > 1 - 1e-12)
    assert area.max() < face_normals(sphere.vertices, sphere.faces)[1].max()
    same = scans.refine(sphere.vertices, sphere.faces, 10)            # fewer asked: the mesh as it is
    assert len(same[1]) == len(sphere.faces)


def test_a_scan_room_stands_on_the_floor_and_loads_back(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=1, radius=3.0)
    scan = Scene("ball", sphere.vertices, sphere.faces, np.full((len(sphere.faces), 3), 0.2),
                 np.zeros((len(sphere.faces), 3)), np.zeros(len(sphere.faces), np.int64), ("ball",))
    room = scans.scan_room(scan, 500)
    box = load("cornell")
    assert len(room.faces) == 500 and room.groups == (*box.groups, "ball")
    ball = room.face_group == len(box.groups)
    points = room.vertices[np.unique(room.faces[ball])]
    assert points[:, 1].min() == -1.0                                   # on the floor's top, not in it
    assert abs(np.ptp(points[:, 1]) - 0.9) < 1e-12
    np.testing.assert_allclose(room.albedo[ball], 0.7)
    assert scans.label(68000) == "68k" and scans.label(1_000_000) == "1m"


def test_the_command_writes_rooms_that_every_command_opens(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=1)
    sphere.export(tmp_path / "ball_scan.ply")
    assert scans.main(["--mesh", str(tmp_path / "ball_scan.ply"), "--triangles", "300", "1000",
                       "--out", str(tmp_path / "rooms")]) == 0
    for name, count in (("ball-room-300.obj", 300), ("ball-room-1k.obj", 1000)):
        room = load(tmp_path / "rooms" / name)
        assert len(room.faces) == count and room.emission.max() > 0      # the box's lamp came along


def test_opening_a_scan_room_is_timed_to_its_probes_first_frame_and_settled_frame(tmp_path):
    """`open_times` drops each scene on the headless viewer and reads the three moments in their order,
    with the resident memory at each, and tabulates the medians against the first scene's."""
    from viewer.bench import open_times
    from viewer.scene import obj, scene_file

    sphere = trimesh.creation.icosphere(subdivisions=1, radius=3.0)
    scan = Scene("ball", sphere.vertices, sphere.faces, np.full((len(sphere.faces), 3), 0.2),
                 np.zeros((len(sphere.faces), 3)), np.zeros(len(sphere.faces), np.int64), ("ball",))
    path = tmp_path / "ball-room.obj"
    obj.write(scans.scan_room(scan, 300), path)
    scenes = [scene_file("cornell"), path]
    results = {"neural": open_times.time_opens("neural", scenes, scene_file("paper-test"), repeats=1)}
    for scene in scenes:
        moments = results["neural"][str(scene)]
        (probes, mb), (first, _), (settled, _) = (moments[m][0] for m in open_times.MOMENTS)
        assert 0 < probes <= first <= settled and mb > 0
    text = open_times.table(results, scenes, 1, "python -m viewer.bench.open_times")
    assert "| neural | cornell | 36 |" in text and "| neural | ball-room | 300 |" in text
    assert "| 1.0x |" in text and text.splitlines()[-1].startswith("| neural | peak |")
