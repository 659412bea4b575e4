"""Spherical harmonics: the fixed basis, quadrature projection and the irradiance convolution, checked
against integrals and closed forms rather than against the module's own output."""

import numpy as np
import pytest

from viewer.probes import sh

UP = np.array([0.0, 1.0, 0.0])


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _random_directions(count, seed):
    return _unit(np.random.default_rng(seed).normal(size=(count, 3)))


# --- the fixed basis ------------------------------------------------------------------------------------

def test_basis_order_and_constants_follow_design():
    x, y, z = np.eye(3)
    s = 1 / np.sqrt(2)
    # (l, m) = 00, 1-1, 10, 11, 2-2, 2-1, 20, 21, 22
    np.testing.assert_allclose(sh.basis(z), [0.282095, 0, 0.488603, 0, 0, 0, 0.630784, 0, 0], atol=1e-12)
    np.testing.assert_allclose(sh.basis(x), [0.282095, 0, 0, 0.488603, 0, 0, -0.315392, 0, 0.546274],
                               atol=1e-12)
    np.testing.assert_allclose(sh.basis(y), [0.282095, 0.488603, 0, 0, 0, 0, -0.315392, 0, -0.546274],
                               atol=1e-12)
    np.testing.assert_allclose(sh.basis([s, s, 0])[4], 1.092548 / 2)      # xy
    np.testing.assert_allclose(sh.basis([0, s, s])[5], 1.092548 / 2)      # yz
    np.testing.assert_allclose(sh.basis([s, 0, s])[7], 1.092548 / 2)      # xz


def test_constants_are_the_normalisation_of_the_real_harmonics():
    exact = [0.5 / np.sqrt(np.pi), np.sqrt(3 / (4 * np.pi)), np.sqrt(15 / (4 * np.pi)),
             np.sqrt(5 / (16 * np.pi)), np.sqrt(15 / (16 * np.pi))]
    np.testing.assert_allclose([0.282095, 0.488603, 1.092548, 0.315392, 0.546274], exact, rtol=2e-6)
    np.testing.assert_allclose(sh.COSINE_LOBE[[0, 1, 4]], [np.pi, 2 * np.pi / 3, np.pi / 4])


@pytest.mark.parametrize("seed", [None, 0, 1])
def test_basis_is_orthonormal_under_lattice_quadrature(seed):
    directions, weights = sh.sphere_directions(4096, seed=seed)
    values = sh.basis(directions)
    gram = values.T @ (values * weights[:, None])
    np.testing.assert_allclose(gram, np.eye(sh.SH_COUNT), atol=1e-3)


def test_sphere_directions_cover_the_sphere_evenly():
    directions, weights = sh.sphere_directions(2000, seed=5)
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(weights.sum(), 4 * np.pi)
    # integral of x^2 over the sphere is 4pi/3, of x (and any odd monomial) is 0
    np.testing.assert_allclose(weights @ directions ** 2, [4 * np.pi / 3] * 3, rtol=1e-3)
    np.testing.assert_allclose(weights @ directions, 0.0, atol=1e-3)
    # the same seed reproduces the same rotation, another seed turns the lattice
    np.testing.assert_array_equal(directions, sh.sphere_directions(2000, seed=5)[0])
    assert np.abs(directions - sh.sphere_directions(2000, seed=6)[0]).max() > 0.1


# --- projection and the irradiance convolution -----------------------------------------------------------

def test_constant_radiance_projects_to_band_zero_and_irradiance_pi_l():
    radiance = np.array([0.5, 2.0, 7.0])
    directions, weights = sh.sphere_directions(4096, seed=2)
    coefficients = sh.project(directions, weights, np.broadcast_to(radiance, (4096, 3)))
    np.testing.assert_allclose(coefficients[0], 0.282095 * 4 * np.pi * radiance, rtol=1e-6)
    np.testing.assert_allclose(coefficients[1:], 0.0, atol=1e-3 * radiance.max())
    normals = _random_directions(200, seed=3)
    np.testing.assert_allclose(sh.irradiance(coefficients, normals),
                               np.broadcast_to(np.pi * radiance, (200, 3)), rtol=2e-4)


def test_clamped_cosine_radiance_irradiance_within_l2_truncation_error():
    """Radiance L(w) = max(0, n0.w): E(n0) = 2pi/3 exactly; L2 gives pi (1/4 + 1/3 + 5/64)."""
    lobe_axis = _unit([0.3, -0.5, 0.8])
    directions, weights = sh.sphere_directions(65536, seed=4)
    radiance = np.maximum(0.0, directions @ lobe_axis)[:, None]
    coefficients = sh.project(directions, weights, radiance)

    np.testing.assert_allclose(sh.irradiance(coefficients, lobe_axis), np.pi * (1 / 4 + 1 / 3 + 5 / 64),
                               rtol=1e-4)

    normals, _ = sh.sphere_directions(300, seed=8)
    receiver_cosine = np.maximum(0.0, normals @ directions.T)                       # (300, n)
    exact = receiver_cosine @ (weights * radiance[:, 0])
    from_sh = sh.irradiance(coefficients, normals)[:, 0]
    # The truncation to bands 0..2 costs at most ~0.8% of the peak irradiance 2pi/3 for this lobe.
    assert np.abs(from_sh - exact).max() < 0.01 * (2 * np.pi / 3)
    # ...and the convolution itself is exact: E from coefficients equals the direct integral of the
    # band-limited radiance against the clamped cosine.
    band_limited = sh.evaluate(coefficients, directions)[:, 0]
    np.testing.assert_allclose(from_sh, receiver_cosine @ (weights * band_limited), atol=1e-4)


def test_delta_source_irradiance_matches_closed_form():
    """E(n) for c = E0 Y(d) is E0 (1/4 + cos t / 2 + 5/16 P2(cos t)) by the addition theorem."""
    irradiance_rgb = np.array([1.0, 3.0, 0.25])
    coefficients = sh.project_delta(UP, irradiance_rgb)
    np.testing.assert_allclose(coefficients, sh.basis(UP)[:, None] * irradiance_rgb, rtol=1e-12)
    np.testing.assert_allclose(sh.irradiance(coefficients, UP), 1.0625 * irradiance_rgb, rtol=1e-5)
    np.testing.assert_allclose(sh.irradiance(coefficients, -UP), 0.0625 * irradiance_rgb, rtol=1e-4)
    np.testing.assert_allclose(sh.irradiance(coefficients, [1.0, 0, 0]), 0.09375 * irradiance_rgb,
                               rtol=1e-4)
    # most negative at cos t = -8/15: -19/480 of the source
    np.testing.assert_allclose(sh.min_irradiance_over_sphere(coefficients), -19 / 480 * irradiance_rgb,
                               rtol=2e-3)


def test_delta_is_the_limit_of_a_small_bright_disc():
    """A 3-degree disc of radiance delivering irradiance E0 to a surface facing it projects like a delta."""
    axis = _unit([1.0, 2.0, -0.5])
    half_angle = np.radians(3.0)
    directions, weights = sh.sphere_directions(400_000, seed=9)
    cosine = directions @ axis
    inside = cosine > np.cos(half_angle)
    # radiance chosen so that the (quadrature) irradiance on a surface facing the disc is exactly 1
    radiance = np.where(inside, 1.0 / np.sum(weights[inside] * cosine[inside]), 0.0)[:, None]
    disc = sh.project(directions, weights, radiance)
    np.testing.assert_allclose(disc, sh.project_delta(axis, [1.0]), atol=0.01 * 0.488603)
    np.testing.assert_allclose(sh.irradiance(disc, axis), 1.0625, rtol=0.01)


def test_band_limited_function_round_trips():
    directions, weights = sh.sphere_directions(4096, seed=10)
    x, y, _ = directions.T
    scale = np.array([1.0, 0.5, 2.0])
    signal = (1 + x + 3 * x * y)[:, None] * scale                                   # (n, 3)
    coefficients = sh.project(directions, weights, signal)
    probes = _random_directions(500, seed=11)
    px, py, _ = probes.T
    np.testing.assert_allclose(sh.evaluate(coefficients, probes), (1 + px + 3 * px * py)[:, None] * scale,
                               atol=1e-3)


def test_project_and_evaluate_batch_over_probes():
    directions, weights = sh.sphere_directions(1024, seed=12)
    rng = np.random.default_rng(13)
    true_coefficients = rng.normal(size=(5, 9, 3))                                  # 5 probes, RGB
    samples = sh.evaluate(true_coefficients, directions[:, None, :])                # (n, 5, 3)
    batch = sh.project(directions, weights, np.moveaxis(samples, 0, 1))            # (5, n, 3) -> (5, 9, 3)
    np.testing.assert_allclose(batch, true_coefficients, atol=2e-3)
    for probe in range(5):
        np.testing.assert_allclose(batch[probe], sh.project(directions, weights, samples[:, probe]))
    # one direction per probe
    per_probe = sh.evaluate(true_coefficients, directions[:5])
    assert per_probe.shape == (5, 3)
    for probe in range(5):
        np.testing.assert_allclose(per_probe[probe], sh.basis(directions[probe]) @ true_coefficients[probe])
    # per-probe direction sets with their own weights
    own = sh.project(np.broadcast_to(directions, (5, 1024, 3)), np.broadcast_to(weights, (5, 1024)),
                     np.moveaxis(samples, 0, 1))
    np.testing.assert_allclose(own, batch)


# --- ringing ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("window", sh.WINDOWS)
def test_dering_strength_zero_is_identity(window):
    coefficients = np.random.default_rng(14).normal(size=(4, 9, 3))
    np.testing.assert_array_equal(sh.dering(coefficients, 0.0, window), coefficients)


@pytest.mark.parametrize("window", sh.WINDOWS)
def test_dering_keeps_mean_and_shrinks_negative_radiance_lobe_of_delta(window):
    delta = sh.project_delta(_unit([0.2, 1.0, 0.3]), [1.0])
    ringing = sh.min_radiance_over_sphere(delta)[0]
    assert ringing < -0.1
    previous = ringing
    for strength in (0.5, 1.0):
        deringed = sh.dering(delta, strength, window)
        assert deringed[0, 0] == delta[0, 0]
        lobe = sh.min_radiance_over_sphere(deringed)[0]
        assert lobe > 0.8 * ringing and lobe > previous        # >= 20% shallower, and more so with strength
        previous = lobe


def test_poussin_dering_bounds_negative_light_by_one_minus_strength():
    delta = sh.project_delta(UP, [1.0])
    radiance_ringing = sh.min_radiance_over_sphere(delta)[0]
    irradiance_ringing = sh.min_irradiance_over_sphere(delta)[0]
    for strength in (0.25, 0.5, 0.75):
        deringed = sh.dering(delta, strength)
        assert sh.min_radiance_over_sphere(deringed)[0] >= (1 - strength) * radiance_ringing - 1e-6
        assert sh.min_irradiance_over_sphere(deringed)[0] >= (1 - strength) * irradiance_ringing - 1e-6
    deringed = sh.dering(delta, 1.0)
    assert sh.min_radiance_over_sphere(deringed)[0] > -1e-6
    assert sh.min_irradiance_over_sphere(deringed)[0] > 0.03        # 1/32 of the source, at the back


def test_window_factors_follow_their_documented_formulas():
    band = sh.BAND_OF
    np.testing.assert_allclose(sh.window_factors(0.5, "poussin"), np.array([1.0, 0.75, 0.55])[band])
    np.testing.assert_allclose(sh.window_factors(1.0, "hanning"), np.array([1.0, 0.75, 0.25])[band])
    lanczos_width_3 = [1.0, np.sin(np.pi / 3) / (np.pi / 3), np.sin(2 * np.pi / 3) / (2 * np.pi / 3)]
    np.testing.assert_allclose(sh.window_factors(1.0, "lanczos"), np.array(lanczos_width_3)[band])
    np.testing.assert_allclose(sh.window_factors(2.0, "hanning"), np.array([1.0, 0.25, 0.0])[band],
                               atol=1e-12)                                # width 1.5: band 2 cut off


def test_fully_deringed_delta_is_the_de_la_vallee_poussin_kernel():
    """Radiance of a unit delta after dering(1) is 3/(4pi) ((1 + cos t)/2)^2: >= 0, integral 1."""
    source = _unit([-0.4, 0.2, 0.9])
    deringed = sh.dering(sh.project_delta(source, [1.0]), 1.0)
    directions = _random_directions(500, seed=18)
    kernel = 3 / (4 * np.pi) * ((1 + directions @ source) / 2) ** 2
    np.testing.assert_allclose(sh.evaluate(deringed, directions)[:, 0], kernel, atol=1e-6)


def test_poussin_dering_makes_any_non_negative_environment_non_negative():
    """A few bright suns over a dim sky ring negative; fully deringed they never shade negative."""
    rng = np.random.default_rng(15)
    suns = sh.project_delta(_random_directions(3, seed=16), rng.uniform(1, 20, size=(3, 3))).sum(axis=0)
    sky = sh.project(*sh.sphere_directions(256), np.full((256, 3), 0.01))
    environment = suns + sky
    assert sh.min_radiance_over_sphere(environment).min() < 0
    deringed = sh.dering(environment, 1.0)
    assert sh.min_radiance_over_sphere(deringed).min() > -1e-5
    assert sh.min_irradiance_over_sphere(deringed).min() > 0


def test_min_irradiance_over_sphere_batches_over_probes():
    coefficients = np.random.default_rng(17).normal(size=(2, 6, 9, 3))
    normals, _ = sh.sphere_directions(4096)
    brute_force = sh.irradiance(coefficients, normals[:, None, None, :]).min(axis=0)
    np.testing.assert_allclose(sh.min_irradiance_over_sphere(coefficients, n=4096), brute_force)


def test_bad_arguments_are_rejected():
    with pytest.raises(ValueError):
        sh.dering(np.zeros((9, 3)), -0.1)
    with pytest.raises(ValueError):
        sh.dering(np.zeros((9, 3)), 1.5, "poussin")
    with pytest.raises(ValueError):
        sh.dering(np.zeros((9, 3)), 0.5, "box")
    with pytest.raises(ValueError):
        sh.evaluate(np.zeros((4, 3)), UP)
