"""The OBJ readers agree: numpy's reader of plain triangles, the bulk reader and the line-by-line reader give
the same scene, bit for bit, on the files each takes (viewer/scene/obj.py)."""

import numpy as np

from viewer.scene import obj
from viewer.scene.geometry import NO_TWIN


def test_an_obj_read_in_bulk_is_the_obj_read_line_by_line(tmp_path):
    """Polygons fanned from their first corner, relative indices beside absolute ones, v/vt/vn corners,
    materials switched between faces, comments and a fourth (w) coordinate: the bulk reader gives the
    line reader's scene, bit for bit."""
    text = ("mtllib m.mtl\n# a comment\nv 0 0 0\nv 1 0 0 1.0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
            "usemtl red\nf 1/1/1 2/1/1 3/1/1 4/1/1\nv 0 0 1\nv 1 0 1\nv 1 1 1\n"
            "usemtl lamp\nf -3 -2 -1 # relative\nusemtl red\nf 5//1 6//1 7//1 3 2\nf 1 2 -1\n")
    bulk, each = read_twice(tmp_path / "mixed.obj", text, obj._read_bulk, obj._read_lines)
    assert bulk is not None and len(bulk.faces) == 2 + 1 + 3 + 1
    assert_same_scene(bulk, each, ("red", "lamp"))


def read_twice(path, text: str, first, second):
    """`text` written to `path` (beside an MTL of two materials, red and lamp), read by two OBJ readers."""
    (path.parent / "m.mtl").write_text("newmtl red\nKd 0.8 0.1 0.1\nnewmtl lamp\nKd 0 0 0\nKe 5 5 5\n")
    path.write_text(text)
    lines = obj._lines(path)
    return first(path, lines), second(path, lines)


def assert_same_scene(a, b, groups):
    for name in ("vertices", "faces", "albedo", "emission", "face_group"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.groups == b.groups == groups


def test_an_obj_of_plain_triangles_is_read_as_the_bulk_reader_reads_it(tmp_path):
    """A file of `v x y z` and `f i j k` lines (materials switched between faces, comments, a w
    coordinate, tabs, normals and texture coordinates beside) is parsed by numpy's reader and gives the
    bulk reader's scene bit for bit; polygons, v/vt/vn corners, relative indices, an indented or broken
    line, or an index past the vertices leave the file to the bulk reader."""
    plain = ("mtllib m.mtl\n# a comment\nv 0 0 0\nv 1 0 0 1.0\nv 1 1 0\nv 0.1 1 0.30000000000000004\nvt 0 0\n"
             "vn 0 0 1\nf 1 2 3\nusemtl red\nf 1\t3 4\ng top\nv 0 0 1e-3\nv 1 0 1 # end\nusemtl lamp\n"
             "f  4 5 6 # lamp\ns off\nusemtl red\nf 1 2 5\n")
    path = tmp_path / "plain.obj"
    fast, bulk = read_twice(path, plain, obj._read_plain, obj._read_bulk)
    assert fast is not None and len(fast.faces) == 4
    assert_same_scene(fast, bulk, ("default", "red", "lamp"))
    for other in ("f 1 2 3 4\n", "f 1/1 2/1 3/1\n", "f 1 2 -1\n", " v 0 0 2\n", "v 0 0\n", "f 1 2 9\n",
                  "f 1 2 x\n", "f 1 2 3 # three\nf 1 3 4 5 # four\n"):
        path.write_text(plain + other)
        assert obj._read_plain(path, obj._lines(path)) is None, other
    assert obj._read_plain(path, ["v 0 0 0", "v 1 0 0"]) is None   # no faces


def test_a_sheet_written_as_two_reversed_polygons_splits_alike_on_both_sides(tmp_path):
    """A two-sided sheet written `f 1 2 3 4` on one side and `f 8 7 6 5` on the other (its own corners, its
    own material; fanned each from its first corner, the two sides would split along different diagonals)
    and a reversed pentagon on shared corners: every triangle gets a reversed twin, whichever reader reads
    the file, and the fronts and the surface covered stay. A polygon without a reversed twin keeps its
    first-corner fan, and a repeated polygon facing the same way is no sheet."""
    text = ("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1.2 1 0\nv 0 1 0\n"
            "v 0 0 0\nv 1 0 0\nv 1.2 1 0\nv 0 1 0\n"
            "v 0 0 2\nv 1 0 2\nv 1.5 0.5 2\nv 1 1 2\nv 0 1 2\n"
            "usemtl red\nf 1 2 3 4\nusemtl lamp\nf 8 7 6 5\n"
            "usemtl red\nf 9 10 11 12 13\nf 11 10 9 13 12\n")
    bulk, each = read_twice(tmp_path / "sheet.obj", text, obj._read_bulk, obj._read_lines)
    assert_same_scene(bulk, each, ("red", "lamp"))
    twin = bulk.twins
    assert np.all(twin[:10] >= 0), twin
    corners = bulk.vertices[bulk.faces]
    for face, other in enumerate(twin[:10]):
        assert sorted(map(tuple, corners[face])) == sorted(map(tuple, corners[other]))
        assert bulk.face_normals[face] @ bulk.face_normals[other] < 0
    # the fronts: the first quad faces +z, the second -z; the pentagons +z and -z; the areas kept
    assert np.allclose(bulk.face_normals[:2, 2], 1) and np.allclose(bulk.face_normals[2:4, 2], -1)
    assert np.isclose(bulk.face_areas[:2].sum(), bulk.face_areas[2:4].sum())
    assert np.isclose(bulk.face_areas[4:7].sum(), bulk.face_areas[7:10].sum())
    lone = obj.read(_written(tmp_path / "lone.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\n"
                                                   "f 2 3 4 1\nf 2 3 4 1\nf 1 5 2 3\n"))
    np.testing.assert_array_equal(lone.faces, [[1, 2, 3], [1, 3, 0]] * 2 + [[0, 4, 1], [0, 1, 2]])
    assert lone.twins is NO_TWIN


def _written(path, text: str):
    path.write_text(text)
    return path
