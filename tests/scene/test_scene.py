"""Loading scenes: the built-in Cornell boxes, the public-domain CornellBox-Original, the box a scene
fills and the scene package's layers (the file formats and bad input: test_scene_files.py)."""

from pathlib import Path

import numpy as np
import pytest
from scenes import group_faces

from viewer import scene
from viewer.scene import SceneError, load

TRAINING = [f"paper-train-{i}" for i in range(1, 6)]
BUILTINS = ["cornell", *TRAINING, "paper-test"]
WALL_NORMALS = {"floor": (0, 1, 0), "ceiling": (0, -1, 0), "back": (0, 0, 1),
                "red-wall": (1, 0, 0), "green-wall": (-1, 0, 0)}
# mitsuba.cornell_box() (mitsuba/python/util.py)
MITSUBA_WHITE = (0.885809, 0.698859, 0.666422)
MITSUBA_RED = (0.570068, 0.0430135, 0.0443706)
MITSUBA_GREEN = (0.105421, 0.37798, 0.076425)
MITSUBA_LIGHT = (18.387, 13.9873, 6.75357)
SHARED_CORNELL = (Path(__file__).parents[3] / "shared" / "scenes" / "cornellbox-original"
                  / "CornellBox-Original.obj")


def group_vertices(s, group):
    return s.vertices[np.unique(s.faces[group_faces(s, group)])]


def emitter_groups(s):
    return [g for g in s.groups if np.any(s.emission[group_faces(s, g)] > 0)]


def object_groups(s):
    return [g for g in s.groups if g not in WALL_NORMALS and g not in emitter_groups(s)]


# ---- built-in scenes -------------------------------------------------------------------------------------

def test_every_builtin_scene_is_shipped():
    assert set(BUILTINS) <= set(scene.builtin_names())


@pytest.mark.parametrize("name", BUILTINS)
def test_builtin_scene_fills_the_unit_box_and_is_lit(name):
    s = load(name)
    lo, hi = s.bounds
    np.testing.assert_allclose(lo, -1, atol=0.011)  # cornell's large box reaches 1 cm into the floor
    np.testing.assert_allclose(hi, 1, atol=1e-9)
    assert s.has_emitters and 1 <= len(emitter_groups(s)) <= 2
    assert s.camera == scene.Camera((0, 0, 3.9), (0, 0, 0), (0, 1, 0), 39.3077)


@pytest.mark.parametrize("name", BUILTINS)
def test_walls_face_into_the_box(name):
    s = load(name)
    for wall, normal in WALL_NORMALS.items():
        np.testing.assert_allclose(s.face_normals[group_faces(s, wall)], np.broadcast_to(normal, (2, 3)),
                                   atol=1e-6, err_msg=wall)


@pytest.mark.parametrize("name", BUILTINS)
def test_lights_hang_below_the_ceiling_facing_down(name):
    s = load(name)
    for light in emitter_groups(s):
        mask = group_faces(s, light)
        np.testing.assert_allclose(s.face_normals[mask], np.broadcast_to((0, -1, 0), (mask.sum(), 3)),
                                   atol=1e-6)
        np.testing.assert_allclose(group_vertices(s, light)[:, 1], 0.99, atol=1e-9)


@pytest.mark.parametrize("name", BUILTINS)
def test_objects_are_closed_and_face_outwards(name):
    s = load(name)
    for group in object_groups(s):
        t = s.triangles[group_faces(s, group)]
        # Divergence theorem: the signed volume is the enclosed volume only for outward faces.
        volume = np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6
        lo, hi = t.reshape(-1, 3).min(0), t.reshape(-1, 3).max(0)
        assert 0.3 * np.prod(hi - lo) < volume <= np.prod(hi - lo) + 1e-9, group


@pytest.mark.parametrize("name", BUILTINS)
def test_each_object_recolours_alone(name):
    s = load(name)
    for group in s.groups:
        recoloured, mask = s.with_albedo(group, (0.1, 0.2, 0.3)), group_faces(s, group)
        np.testing.assert_allclose(recoloured.albedo[mask], np.broadcast_to((0.1, 0.2, 0.3), (mask.sum(), 3)))
        np.testing.assert_array_equal(recoloured.albedo[~mask], s.albedo[~mask])


def test_cornell_uses_mitsubas_colours_and_light():
    s = load("cornell")
    expected = {"floor": MITSUBA_WHITE, "ceiling": MITSUBA_WHITE, "back": MITSUBA_WHITE,
                "red-wall": MITSUBA_RED, "green-wall": MITSUBA_GREEN, "small-box": MITSUBA_WHITE,
                "large-box": MITSUBA_WHITE, "light": MITSUBA_WHITE}
    assert set(s.groups) == set(expected)
    for group, albedo in expected.items():
        np.testing.assert_allclose(s.group_albedo(group), albedo, rtol=1e-9, err_msg=group)
    np.testing.assert_allclose(s.emission[group_faces(s, "light")], [MITSUBA_LIGHT] * 2, rtol=1e-9)
    np.testing.assert_array_equal(s.emission[~group_faces(s, "light")], 0)


@pytest.fixture
def mitsuba():
    mi = pytest.importorskip("mitsuba", reason="the `reference` extra (mitsuba) is not installed")
    previous = mi.variant()
    mi.set_variant("scalar_rgb")
    yield mi
    if previous:  # other tests may rely on the variant they chose
        mi.set_variant(previous)


def test_cornell_geometry_matches_mitsuba(mitsuba):
    reference = mitsuba.cornell_box()
    s = load("cornell")
    for group in s.groups:
        shape = dict(reference[group], bsdf={"type": "diffuse"})
        shape.pop("emitter", None)
        mesh = mitsuba.load_dict(shape)
        positions = np.array(mesh.vertex_positions_buffer(), np.float64).reshape(-1, 3)
        faces = np.array(mesh.faces_buffer(), np.int64).reshape(-1, 3)
        np.testing.assert_allclose(np.unique(group_vertices(s, group).round(5), axis=0),
                                   np.unique(positions.round(5), axis=0), atol=2e-6, err_msg=group)
        t = positions[faces]
        normals = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        np.testing.assert_allclose(np.unique(s.face_normals[group_faces(s, group)].round(4), axis=0),
                                   np.unique(normals.round(4), axis=0), atol=1e-4, err_msg=group)
        area = np.ravel(mesh.surface_area())[0]
        assert s.face_areas[group_faces(s, group)].sum() == pytest.approx(area, rel=1e-5), group


def test_paper_test_is_cornell_with_a_pink_back_wall_and_one_new_object():
    cornell, test = load("cornell"), load("paper-test")
    np.testing.assert_allclose(test.group_albedo("back"), (0.85, 0.45, 0.55))
    for group in cornell.groups:
        if group != "back":
            np.testing.assert_allclose(test.vertices[test.faces[group_faces(test, group)]],
                                       cornell.vertices[cornell.faces[group_faces(cornell, group)]])
            np.testing.assert_allclose(test.group_albedo(group), cornell.group_albedo(group))
    assert len(set(test.groups) - set(cornell.groups)) == 1


def test_paper_test_puts_its_new_object_where_no_training_layout_has_one():
    cornell, test = load("cornell"), load("paper-test")
    (new,) = set(test.groups) - set(cornell.groups)
    new_vertices = group_vertices(test, new)
    for name in TRAINING:
        s = load(name)
        for group in object_groups(s):
            v = group_vertices(s, group)
            gap = np.maximum(v.min(0) - new_vertices.max(0), new_vertices.min(0) - v.max(0))
            assert gap.max() > 0, f"{name}/{group} overlaps the held-out {new}"


def test_training_layouts_differ_from_each_other_and_from_cornell():
    def layout(name):
        s = load(name)
        return np.sort(np.concatenate([group_vertices(s, g).mean(0) for g in object_groups(s)]).round(3))

    layouts = {name: layout(name) for name in ["cornell", *TRAINING]}
    for i, a in enumerate(layouts):
        for b in list(layouts)[i + 1:]:
            assert layouts[a].shape != layouts[b].shape or not np.allclose(layouts[a], layouts[b]), (a, b)


# ---- the public-domain CornellBox-Original (Williams College, 2011) --------------------------------------

@pytest.fixture
def original_cornell():
    if not SHARED_CORNELL.parent.is_dir():
        pytest.skip(f"{SHARED_CORNELL.parent} not found (CI clones the repo with shared/ beside it)")
    return load(SHARED_CORNELL)


def test_original_cornell_light_emits_downwards(original_cornell):
    s = original_cornell
    light = group_faces(s, "light")
    np.testing.assert_allclose(s.emission[light], [[17, 12, 4]] * light.sum())
    np.testing.assert_array_equal(s.emission[~light], 0)
    np.testing.assert_allclose(s.face_normals[light], [[0, -1, 0]] * light.sum(), atol=1e-9)
    np.testing.assert_allclose(s.triangles[light][..., 1], 1.98)


def test_original_cornell_walls_face_inwards(original_cornell):
    s = original_cornell
    directions = {"floor": (0, 1, 0), "ceiling": (0, -1, 0), "backWall": (0, 0, 1),
                  "leftWall": (1, 0, 0), "rightWall": (-1, 0, 0)}
    for group, direction in directions.items():
        assert np.all(s.face_normals[group_faces(s, group)] @ direction > 0.99), group
    np.testing.assert_allclose(s.group_albedo("leftWall"), (0.63, 0.065, 0.05))
    lo, hi = s.bounds
    np.testing.assert_allclose(lo, (-1.02, 0, -1.04))
    np.testing.assert_allclose(hi, (1.0, 1.99, 0.99))


# ---- the box a scene fills --------------------------------------------------------------------------------

def write_obj(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_a_flat_scene_gets_a_box_with_depth_centred_on_its_plane(tmp_path):
    floor = load(write_obj(tmp_path / "floor.obj", "v -2 0.5 -1\nv 2 0.5 -1\nv 2 0.5 1\nf 1 3 2\n"))
    lo, hi = floor.bounds
    np.testing.assert_allclose(lo, [-2, -1.5, -1])
    np.testing.assert_allclose(hi, [2, 2.5, 1])


def test_coordinates_beyond_float32_are_refused(tmp_path):
    with pytest.raises(SceneError, match="float32"):
        load(write_obj(tmp_path / "huge.obj", "v 0 0 0\nv 3e38 0 0\nv 0 3e38 0\nf 1 2 3\n"))


# ---- module layers ---------------------------------------------------------------------------------------

def viewer_imports(module: str) -> set[str]:
    """The viewer modules one module of viewer/scene/ imports anywhere in its file (inside functions too),
    as names inside the scene package ("types", "obj", ...)."""
    import ast

    tree = ast.parse((Path(__file__).parents[2] / "viewer" / "scene" / f"{module}.py").read_text())
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            found |= {node.module} | {f"{node.module}.{a.name}" for a in node.names}
    return {name.split(".")[2] for name in found if name.startswith("viewer.scene.")}


def test_scene_modules_import_downwards_only():
    """The data type at the bottom, the file formats above it, the dispatch on top: no import circle."""
    formats = {"obj", "loaders", "gltf"}
    assert viewer_imports("types").isdisjoint(formats | {"loading"})
    for module in formats:
        assert "types" in viewer_imports(module)
        assert viewer_imports(module).isdisjoint((formats - {module}) | {"loading"}), module
    assert formats | {"types"} <= viewer_imports("loading")
