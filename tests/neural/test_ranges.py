"""The wide ranges (`ranges.PRESETS["v2"]`): every room is a closed box open at the front,
its lights (on any surface, objects included) shine into it with the power drawn, and it is the same
room for the same seed."""

from __future__ import annotations

from collections import Counter

import numpy as np

from scenes import assert_same_room, covered, group_faces, wall_samples
from viewer.scene import meshes
from viewer.evaluation import procedural
from viewer.evaluation.procedural import CORNELL_POWER, WALL_NAMES, random_scene
from viewer.neural.ranges import LIGHT_SURFACES, PRESETS, V2

SEEDS = range(60)


def wide(seed: int):
    return random_scene(np.random.default_rng([11, seed]), f"wide-{seed}", V2)


def solids(scene, params):
    """(name, vertices) of every object and partition."""
    names = [o for o in scene.groups if o not in WALL_NAMES and not o.startswith("light")]
    return [(n, np.unique(scene.triangles[group_faces(scene, n)].reshape(-1, 3), axis=0)) for n in names]


def test_presets_keep_v1_as_the_default():
    assert PRESETS["v1"] == procedural.Ranges() and PRESETS["v2"] is V2
    assert V2.albedo == (0.01, 0.95) and V2.lights == (1, 3) and set(V2.light_surfaces) == set(LIGHT_SURFACES)


def test_walls_are_closed_except_the_front_and_the_window():
    for seed in range(20):
        scene, params = wide(seed)
        for name in WALL_NAMES:
            _, points, hole = wall_samples(params, name, 16)
            on_wall = covered(points, scene.triangles[group_faces(scene, name)])
            np.testing.assert_array_equal(on_wall, ~hole, err_msg=f"seed {seed} {name}")


def test_lights_on_every_surface_shine_into_the_room_with_the_power_drawn():
    surfaces, counts = Counter(), Counter()
    for seed in SEEDS:
        scene, params = wide(seed)
        half = np.array(params["room_half"])
        emitting = np.any(scene.emission > 0, axis=1)
        assert 1 <= len(params["lights"]) <= 3, f"seed {seed}"
        counts[len(params["lights"])] += 1
        power = np.pi * np.sum(scene.face_areas[emitting] * scene.emission[emitting].mean(axis=1))
        drawn = sum(light["power"] for light in params["lights"]) * CORNELL_POWER
        assert np.isclose(power, drawn, rtol=1e-9) and power <= V2.light_power[1] * CORNELL_POWER * 1.001
        inside = [v for _, v in solids(scene, params)]
        for light in params["lights"]:
            surfaces[light["wall"]] += 1
            if light["wall"] == "object":  # a closed object that glows: its faces point out, into the room
                mask = group_faces(scene, light["object"])
                assert meshes.signed_volume((scene.vertices, scene.faces[mask])) > 0
                assert np.all(scene.emission[mask] > 0)
        # a rectangle light hangs inside the room, facing into it, and its front is inside no object
        for face in np.flatnonzero(emitting):
            if scene.groups[scene.face_group[face]].startswith("light"):
                centre = scene.triangles[face].mean(axis=0)
                front = centre + 0.02 * scene.face_normals[face]
                assert np.all(np.abs(centre) < half), f"seed {seed}: a light behind a wall"
                assert np.all(np.abs(front) < half), f"seed {seed}: a light faces out of the room"
                assert not any(np.all((front > v.min(0)) & (front < v.max(0))) for v in inside), f"seed {seed}"
    assert set(surfaces) == set(LIGHT_SURFACES) and set(counts) == {1, 2, 3}


def test_albedo_partitions_objects_and_proportions_cover_the_ranges():
    walls, ratios, partitioned = [], [], 0
    for seed in SEEDS:
        scene, params = wide(seed)
        half = np.array(params["room_half"])
        assert np.all((half >= 0.6) & (half <= 1.8))
        ratios.append(half.max() / half.min())
        lit = np.any(scene.emission > 0, axis=1) & np.array([scene.groups[g].startswith("light")
                                                             for g in scene.face_group])
        assert np.all((scene.albedo[~lit] >= 0.01) & (scene.albedo[~lit] <= 0.95)), f"seed {seed}"
        walls += [np.mean(params["walls"][w]) for w in WALL_NAMES]
        assert len(params["objects"]) <= 6 and len(params["partitions"]) <= 2
        partitioned += bool(params["partitions"])
        for p in params["partitions"]:
            assert min(p["half"]) <= 0.025 and p["centre"][1] - p["half"][1] >= -half[1] - 1e-9
            assert p["centre"][1] + p["half"][1] < half[1] - procedural.WALL_GAP
        pieces = solids(scene, params)
        for i, (a, va) in enumerate(pieces):
            for b, vb in pieces[i + 1:]:
                assert not meshes.overlap(va, vb), f"seed {seed}: {a} overlaps {b}"
        # nothing stands on a floor light
        for light in params["lights"]:
            if light["wall"] == "floor":
                mask = group_faces(scene, next(g for g in scene.groups if g.startswith("light")
                                               and np.allclose(scene.emission[group_faces(scene, g)][0],
                                                               light["radiance"])))
                lo, hi = scene.triangles[mask].reshape(-1, 3).min(0), scene.triangles[mask].reshape(-1, 3).max(0)
                for name, v in pieces:
                    on_floor = v[:, 1].min() < -half[1] + 1e-6
                    assert not (on_floor and procedural.on_clear(v, [(lo[0], hi[0], lo[2], hi[2])])), name
    assert min(walls) < 0.1 and max(walls) > 0.85
    assert max(ratios) > 2.0 and 0.3 < partitioned / len(SEEDS) < 0.9


def test_rooms_load_and_their_lights_reach_the_probes():
    from viewer.physical import gi

    for seed in range(4):
        scene, params = wide(seed)
        total, reflected = gi.solve_parts(scene, gi.GISettings(voxels=16, probes=8, directions=64))
        direct = total.coefficients - reflected.coefficients
        assert np.all(np.isfinite(total.coefficients)) and total.valid.sum() > 0.5 * total.valid.size
        l00 = direct[total.valid][:, 0].mean(axis=-1)
        assert np.mean(l00 > 0) > 0.3, f"seed {seed}: the lights reach few probes"
        assert np.all(reflected.coefficients[total.valid][:, 0].mean(axis=-1) > 0), f"seed {seed}"


def test_the_same_seed_draws_the_same_room():
    a, pa = wide(5)
    b, pb = wide(5)
    c, _ = wide(6)
    assert_same_room(a, pa, b, pb)
    assert a.vertices.shape != c.vertices.shape or not np.array_equal(a.vertices, c.vertices)
