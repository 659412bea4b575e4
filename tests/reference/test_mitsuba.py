"""The Mitsuba ground truth checked against physics with known answers, not against its own output.

White furnace (closed box, albedo 1/2, every surface emitting 1: L = 2 everywhere), a sun on a floor
(irradiance E cos(theta), SH = E Y(sun) plus the floor's analytic glow), a one-sided emitter seen from
its front and its back, and a small Cornell-like render (light where the camera model puts it, red wall
on the left).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from viewer.probes import sh
from viewer.scene import Camera, DirectionalLight, Scene

reference = pytest.importorskip("viewer.reference.mitsuba")
pytest.importorskip("mitsuba")

REPO = Path(__file__).resolve().parents[2]


# ---- scenes built from quads ------------------------------------------------------------------------

def quad(corner, u, v):
    """Two triangles spanning corner + [0,1]u + [0,1]v; front (CCW) side along cross(u, v)."""
    c, u, v = (np.asarray(x, np.float64) for x in (corner, u, v))
    return np.array([c, c + u, c + u + v, c + v]), np.array([[0, 1, 2], [0, 2, 3]])


def build(name, parts, sun=None, camera=None) -> Scene:
    """parts: (quad, albedo, emission) triples -> one Scene, a group per part."""
    vertices, faces, albedo, emission = [], [], [], []
    for k, ((v, f), a, e) in enumerate(parts):
        faces.append(f + 4 * k)
        vertices.append(v)
        albedo += [a] * 2
        emission += [e] * 2
    return Scene(name, np.concatenate(vertices), np.concatenate(faces), np.array(albedo, float),
                 np.array(emission, float), np.repeat(np.arange(len(parts)), 2),
                 tuple(f"part{k}" for k in range(len(parts))), sun=sun, camera=camera or Camera())


def inward_box_faces(skip=()):
    """The six faces of [-1, 1]^3 with their fronts facing inwards, as (name, quad)."""
    out = []
    for axis in range(3):
        b, c = np.eye(3)[(axis + 1) % 3], np.eye(3)[(axis + 2) % 3]   # cross(b, c) = +axis
        for side in (-1, 1):
            corner = -np.ones(3)
            corner[axis] = side
            u, v = (2 * b, 2 * c) if side < 0 else (2 * c, 2 * b)   # normal = -side * axis: inwards
            name = ("-" if side < 0 else "+") + "xyz"[axis]
            if name not in skip:
                out.append((name, quad(corner, u, v)))
    return out


def covered(hits, f=sh.basis, count=400_000):
    """integral of f(w) over the directions w with hits(w), by a dense Fibonacci quadrature."""
    directions, weights = sh.sphere_directions(count)
    mask = hits(directions)
    values = f(directions[mask])
    return np.tensordot(weights[mask], values, axes=1)


# ---- white furnace ----------------------------------------------------------------------------------

FURNACE = build("furnace", [(q, (0.5,) * 3, (1.0,) * 3) for _, q in inward_box_faces()])
FREE_POINTS = np.array([[0.0, 0.0, 0.0], [0.5, -0.3, 0.2], [-0.7, 0.7, 0.6]])


def test_white_furnace_probes_see_radiance_two_everywhere():
    c = reference.probe_sh(FURNACE, FREE_POINTS, directions=65536, cache=False)
    assert c.shape == (3, 9, 3) and c.dtype == np.float32
    directions, _ = sh.sphere_directions(200, seed=1)
    radiance = sh.evaluate(c, directions[:, None, :])                # (200, P, 3)
    np.testing.assert_allclose(radiance, 2.0, rtol=0.02)
    np.testing.assert_allclose(sh.irradiance(c, directions[:, None, :]), 2 * np.pi, rtol=0.02)


def test_white_furnace_surface_irradiance_is_two_pi():
    points = np.array([[0.1, -1.0, 0.2], [1.0, 0.3, -0.4], [-0.5, 0.5, 1.0]])
    normals = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    e = reference.irradiance(FURNACE, points, normals, spp=4096, cache=False)
    np.testing.assert_allclose(e, 2 * np.pi, rtol=0.02)
    # Half of L = 2 is the walls' own emission (1), half the light they reflect: indirect E = pi.
    indirect = reference.irradiance(FURNACE, points, normals, spp=4096, cache=False, indirect_only=True)
    np.testing.assert_allclose(indirect, np.pi, rtol=0.02)


# ---- a sun on a floor -------------------------------------------------------------------------------

SUN = DirectionalLight([0.3, 1.0, 0.2], [3.0, 2.0, 1.0])
FLOOR_ALBEDO = np.array([0.5, 0.4, 0.3])
FLOOR = build("floor", [(quad([-1, 0, -1], [0, 0, 2], [2, 0, 0]), FLOOR_ALBEDO, (0.0,) * 3)], sun=SUN)


def test_sun_irradiance_on_floor_is_e_cos_theta_and_zero_below():
    cos_theta = SUN.direction[1]
    points = np.array([[0.0, 0.0, 0.0], [0.6, 0.0, -0.7], [0.0, 0.0, 0.0]])
    normals = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    e = reference.irradiance(FLOOR, points, normals, spp=256, cache=False)
    np.testing.assert_allclose(e[:2], np.tile(SUN.irradiance * cos_theta, (2, 1)), rtol=0.02)
    np.testing.assert_allclose(e[2], 0.0, atol=1e-6)        # under the floor: the sun is blocked


ABOVE_FLOOR = np.array([0.2, 0.5, -0.1])
FLOOR_GLOW = FLOOR_ALBEDO / np.pi * SUN.irradiance * SUN.direction[1]   # Lambertian, fully lit floor


def hits_floor(w):
    """Directions from ABOVE_FLOOR that see the floor square."""
    t = -ABOVE_FLOOR[1] / np.minimum(w[:, 1], -1e-12)     # distance to the plane y = 0 (if w.y < 0)
    x, z = ABOVE_FLOOR[0] + t * w[:, 0], ABOVE_FLOOR[2] + t * w[:, 2]
    return (w[:, 1] < 0) & (np.abs(x) <= 1) & (np.abs(z) <= 1)


def test_probe_above_floor_holds_the_sun_delta_and_the_floor_glow():
    c = reference.probe_sh(FLOOR, [ABOVE_FLOOR, -ABOVE_FLOOR], directions=2048, cache=False)
    expected = sh.project_delta(SUN.direction, SUN.irradiance) + covered(hits_floor)[:, None] * FLOOR_GLOW
    np.testing.assert_allclose(c[0], expected, atol=0.01 * np.abs(expected).max())
    np.testing.assert_allclose(c[1], 0.0, atol=1e-6)        # under the floor: no sun, a dark underside


def test_irradiance_for_tilted_normals_above_floor():
    """Free-space point, normals in every direction: E(n) = E_sun max(0, n.s) + glow * integral over
    the floor's solid angle of max(0, n.w) (checks the cosine sampling about an arbitrary normal)."""
    normals, _ = sh.sphere_directions(6, seed=2)
    e = reference.irradiance(FLOOR, np.tile(ABOVE_FLOOR, (6, 1)), normals, spp=2048, cache=False)
    for n, measured in zip(normals, e):
        floor = covered(hits_floor, lambda w: np.clip(w @ n, 0.0, None))
        expected = SUN.irradiance * max(float(n @ SUN.direction), 0.0) + floor * FLOOR_GLOW
        np.testing.assert_allclose(measured, expected, rtol=0.02, atol=0.005)


# ---- one-sided area emitter -------------------------------------------------------------------------

def square_facing(origin_side: bool, half=0.4, distance=1.0, radiance=5.0):
    corner, u, v = [-half, -half, -distance], [2 * half, 0, 0], [0, 2 * half, 0]   # front: +z
    if not origin_side:
        u, v = v, u
    return build("square", [(quad(corner, u, v), (0.5,) * 3, (radiance,) * 3)])


def test_one_sided_emitter_lights_only_its_front():
    def hits_square(w):
        t = -1.0 / np.minimum(w[:, 2], -1e-12)        # distance to the plane z = -1 (if w.z < 0)
        return (w[:, 2] < 0) & (np.abs(t * w[:, 0]) <= 0.4) & (np.abs(t * w[:, 1]) <= 0.4)

    origin = np.zeros((1, 3))
    front = reference.probe_sh(square_facing(True), origin, directions=4096, cache=False)[0]
    expected = 5.0 * covered(hits_square)
    solid_angle = 4 * np.arcsin(0.4 ** 2 / (0.4 ** 2 + 1.0))       # square of half-side a at d: 4 asin(a^2/(a^2+d^2))
    assert expected[0] == pytest.approx(5.0 * 0.282095 * solid_angle, rel=1e-3)
    np.testing.assert_allclose(front, np.tile(expected[:, None], 3), atol=0.02 * expected[0])
    back = reference.probe_sh(square_facing(False), origin, directions=1024, cache=False)[0]
    np.testing.assert_allclose(back, 0.0, atol=1e-6)


# ---- rendering --------------------------------------------------------------------------------------

def test_render_shows_the_light_where_the_camera_model_puts_it():
    colours = {"-x": (0.6, 0.05, 0.05), "+x": (0.05, 0.6, 0.05)}
    parts = [(q, colours.get(name, (0.7,) * 3), (0.0,) * 3) for name, q in inward_box_faces(skip={"+z"})]
    light = quad([-0.25, 0.98, -0.25], [0.5, 0, 0], [0, 0, 0.5])      # front faces down (-y)
    parts.append((light, (0.5,) * 3, (10.0,) * 3))
    camera = Camera(origin=(0.0, 0.0, 3.5), target=(0.0, 0.0, 0.0), fov=40.0)
    scene = build("cornell-like", parts, camera=camera)
    image = reference.render(scene, width=96, height=64, spp=16, cache=False)
    assert image.shape == (64, 96, 3) and image.dtype == np.float32
    assert np.all(np.isfinite(image)) and image.min() >= 0.0
    # The light's centre (0, 0.98, 0) lies at y_ndc = 0.98/3.5/tan(20 deg) = 0.77 (vertical fov):
    # pixel row (1 - 0.77)/2 * 64 = 7.4, column 48. There the camera sees the emitter itself.
    row = int((1 - 0.98 / 3.5 / np.tan(np.radians(20))) / 2 * 64)
    assert np.all(image[row, 46:51] >= 10.0 * 0.999)
    assert image[row, 46:51].mean() > 5 * image.mean()
    # The side walls span |x_ndc| = 1/(4.5 tan(20) 1.5) .. 1/(2.5 tan(20) 1.5) = 0.41 .. 0.73: columns
    # 13-28 on the left. Mitsuba's camera looks down -z with x flipped; look_at must undo that.
    left, right = image[20:44, 16:26].mean(axis=(0, 1)), image[20:44, -26:-16].mean(axis=(0, 1))
    assert left[0] > 3 * left[1] and right[1] > 3 * right[0]        # red wall left, green right


# ---- plumbing ---------------------------------------------------------------------------------------

def test_in_kernel_sh_basis_matches_viewer_sh():
    directions, _ = sh.sphere_directions(64, seed=3)
    np.testing.assert_allclose(np.stack(reference._basis(directions.T), axis=-1), sh.basis(directions),
                               atol=1e-12)


def test_cache_reuses_results_and_keys_on_inputs(tmp_path, monkeypatch):
    monkeypatch.setenv("GI_VIEWER_REFERENCE_CACHE_DIR", str(tmp_path))
    first = reference.probe_sh(FLOOR, [[0, 0.5, 0]], directions=64)
    assert len(list(tmp_path.glob("probe_sh-*.npy"))) == 1
    np.testing.assert_array_equal(reference.probe_sh(FLOOR, [[0, 0.5, 0]], directions=64), first)
    reference.probe_sh(FLOOR.with_albedo("part0", (0.2, 0.2, 0.2)), [[0, 0.5, 0]], directions=64)
    reference.probe_sh(FLOOR, [[0, 0.5, 0]], directions=64, seed=1)
    assert len(list(tmp_path.glob("probe_sh-*.npy"))) == 3
    monkeypatch.setenv("GI_VIEWER_REFERENCE_CACHE", "0")
    reference.probe_sh(FLOOR, [[0, 0.4, 0]], directions=64)
    assert len(list(tmp_path.glob("*.npy"))) == 3


def test_missing_mitsuba_names_the_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "mitsuba", None)        # makes `import mitsuba` fail
    with pytest.raises(reference.ReferenceUnavailable, match="pip install mitsuba"):
        reference.probe_sh(FLOOR, [[0, 0.5, 0]], directions=16, cache=False)


def test_numpy_core_does_not_import_mitsuba():
    core = [m for m in ("sh", "scene", "voxels", "probes", "transport", "loaders")
            if (REPO / "viewer" / f"{m}.py").exists()]
    code = ("import sys\n" + "".join(f"import viewer.{m}\n" for m in core)
            + "bad = [m for m in ('mitsuba', 'drjit', 'viewer.reference.mitsuba') if m in sys.modules]\n"
            + "assert not bad, bad\n")
    subprocess.run([sys.executable, "-c", code], cwd=REPO, check=True)


def test_scalar_variant_fallback_agrees():
    """scalar_rgb (no LLVM) runs the same estimator one lane at a time: the furnace still reads 2."""
    code = ("import numpy as np\nfrom viewer.reference import mitsuba as reference\nfrom viewer.probes import sh\n"
            "from tests.reference.test_mitsuba import FURNACE\n"
            "c = reference.probe_sh(FURNACE, [[0.1, 0.2, 0.3]], directions=512, cache=False)\n"
            "print(reference.variant(), float(sh.irradiance(c[0], [0.0, 1.0, 0.0])[0] / (2 * np.pi)))\n")
    env = dict(os.environ, GI_VIEWER_MITSUBA_VARIANT="scalar_rgb")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, check=True,
                         capture_output=True, text=True).stdout.split()
    assert out[0] == "scalar_rgb"
    assert float(out[1]) == pytest.approx(1.0, rel=0.04)


def test_each_side_of_a_two_sided_sheet_shows_its_own_face():
    """Two faces on the same corners wound opposite ways, white and green: Mitsuba met one of them from
    both sides (green from both); pulled a hair apart (`sheets_apart`), each side shows its own, and a
    scene without such faces is converted as it is."""
    from viewer.reference.conversion import SHEET_GAP, sheets_apart

    corners = np.array([[0.4, 1.0, -1.0], [0.4, 1.0, 1.0], [0.4, -0.6, 1.0], [0.4, -0.6, -1.0]])   # light passes under
    faces = np.array([[0, 2, 1], [0, 3, 2], [0, 1, 2], [0, 2, 3]])   # white towards -x, green towards +x
    albedo = np.array([[0.8] * 3] * 2 + [[0.2, 0.7, 0.2]] * 2)
    sheet = Scene("sheet", corners, faces, albedo, np.zeros((4, 3)), np.zeros(4, np.int64), ("sheet",))
    parts = [(q, (0.5,) * 3, (0.0,) * 3) for _, q in inward_box_faces(skip=set())]
    parts.append((quad([-0.25, 0.98, -0.25], [0.5, 0, 0], [0, 0, 0.5]), (0.5,) * 3, (10.0,) * 3))
    room = build("room", parts)
    scene = Scene.concatenate("sheet-room", [room, sheet])
    apart = sheets_apart(scene)
    moved = np.abs(apart.triangles - scene.triangles).max(axis=(1, 2))
    diagonal = float(np.linalg.norm(scene.bounds[1] - scene.bounds[0]))
    np.testing.assert_allclose(moved[-4:], SHEET_GAP * diagonal, rtol=1e-6)
    assert np.all(moved[:-4] == 0) and sheets_apart(room) is room
    for origin, white in (((-0.6, 0.0, 0.0), True), ((0.9, 0.0, 0.0), False)):
        image = reference.render(scene, Camera(origin=origin, target=(0.4, 0.3, 0.0), fov=30.0), 16, 16, 64,
                                 cache=False)
        r, g, _ = image[4:12, 4:12].reshape(-1, 3).mean(axis=0)
        assert (r / g > 0.9) if white else (r / g < 0.4)   # green reflects 0.2 / 0.7 of red to green, or less
