"""The neural GI source: export fidelity, probes in radiance units and after edits, the viewer's source, and
the symmetries the training relies on (the model card and bad models: test_model_card.py)."""

import json
import shutil

import numpy as np
import pytest

from viewer.neural import encoding
from viewer.neural import field as neural
from viewer.scene import Scene, load
from viewer.rays.voxels import voxelize

torch = pytest.importorskip("torch", reason="the train extra (torch) is needed to build models in tests")

from viewer.training import export  # noqa: E402 - needs torch
from viewer.training.batches import mirror_links  # noqa: E402
from viewer.training.train import mirror  # noqa: E402
from tiny_network import export_tiny  # noqa: E402 - needs torch


def encoded(scene: Scene, m: int = 8, direct_shadows: bool = True) -> encoding.Encoding:
    return encoding.encode_scene(scene, m, 16, direct_shadows=direct_shadows)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A random model exported with a card, as the training pipeline writes it."""
    return export_tiny(tmp_path_factory.mktemp("models"))


def test_onnx_equals_torch(exported):
    model, path = exported
    inputs = encoded(load("cornell")).inputs
    assert export.max_difference(model, path, inputs) < 1e-5


def test_a_network_of_one_input_gives_the_same_probes(exported, tmp_path):
    """Networks are exported with the asinh of their inputs as a second input (numpy computes it faster
    than the ONNX operators) and their seen filter's products as two more (compiled code computes them
    faster than onnxruntime's grouped 3D convolution); a network that computes all of it itself, as
    earlier exports did, still loads and gives the same probes where the filter stops at no wall (its
    graph cannot stop it: `network_feed.WallTaps`)."""
    model, path = exported
    single = tmp_path / "single.onnx"
    example = torch.zeros(3, encoding.CHANNELS, 8, 8, 8)
    lattice = {0: "passes", 2: "m", 3: "m", 4: "m"}
    torch.onnx.export(model, (example,), str(single), input_names=["inputs"], output_names=["probes"],
                      dynamic_axes={"inputs": lattice, "probes": lattice}, dynamo=False)
    card = json.loads(path.with_suffix(".json").read_text())
    card.update(file=single.name, sha256=neural.file_sha256(single))
    single.with_suffix(".json").write_text(json.dumps(card))
    one, two = neural.NeuralField(single), neural.NeuralField(path)
    assert one.input_names == ["inputs"]
    assert two.input_names == ["inputs", "compressed", "seen_filtered", "bounce_filtered"]
    inputs = encoded(load("cornell")).inputs
    reference = two.run(inputs)   # the two spell asinh apart: float32 round-off, through the network
    np.testing.assert_allclose(one.run(inputs), reference, rtol=1e-4, atol=1e-4 * np.abs(reference).max())


def test_neural_field_gives_probes_in_radiance_units(exported):
    model, path = exported
    field = neural.NeuralField(path)
    scene = load("cornell")
    grid = field.solve(scene)
    assert grid.coefficients.shape == (8, 8, 8, 9, 3) and np.all(np.isfinite(grid.coefficients))
    assert field.card.direct_shadows == encoding.DIRECT_SHADOWS   # as the export writes it
    enc = encoded(scene, direct_shadows=field.card.direct_shadows)
    with torch.no_grad():   # the viewer's filter stops at walls as training's does
        out = model(torch.from_numpy(enc.inputs), links=torch.from_numpy(enc.links[None])).numpy()
    out = (out[:, :18] * enc.scale[:, None, None, None, None]).transpose(2, 3, 4, 1, 0)
    if field.card.direct_shadows:
        expected = out[..., :9, :]
    else:   # all the light: the probes' direct light with its shadows, and the network's reflected light
        voxels = voxelize(scene, 16)
        direct = encoding.probe_direct(voxels, scene.sun, *scene.bounds, 8, encoding.occluders(scene, voxels))
        expected = out[..., 9:, :] + direct.reshape(8, 8, 8, 9, 3)
    # the live encoder and `encode` sum the lamps' terms in their own orders: their inputs differ by
    # float32 ulps (4e-6 of 18 at most), which a random network carries to its outputs
    np.testing.assert_allclose(grid.coefficients, expected, rtol=1e-4, atol=1e-5 * np.abs(expected).max())
    reflected = field.solve(scene, include_emitted=False).coefficients
    np.testing.assert_allclose(reflected, out[..., 9:, :], rtol=1e-4, atol=1e-5 * np.abs(out).max())
    assert not np.allclose(reflected, grid.coefficients)


def test_brighter_lamp_gives_exactly_brighter_probes(exported):
    """Linearity in the emitted light holds by construction (the encoding's scale), for any weights."""
    _, path = exported
    field = neural.NeuralField(path)
    scene = load("cornell")
    light = scene.group_index("light")
    brighter = scene.with_emission("light", 3 * scene.emission[scene.face_group == light][0])
    np.testing.assert_allclose(field.solve(brighter).coefficients, 3 * field.solve(scene).coefficients,
                               rtol=1e-4, atol=1e-5)


def test_dark_scene_gives_zero_probes(exported):
    _, path = exported
    from scenes import box

    grid = neural.NeuralField(path).solve(box(inward=True, albedo=0.5, name="dark"))
    assert np.all(grid.coefficients == 0)


def test_predictions_after_edits_equal_fresh_ones(exported):
    """The kept encoder and the reused network passes change no number: after each edit the probes
    are those of a prediction from scratch; a lamp's colour edit runs no pass of the network."""
    _, path = exported
    field = neural.NeuralField(path)
    scene = load("cornell")
    lo, hi = scene.bounds
    lamp = scene.emission[scene.face_group == scene.group_index("light")][0]
    matrix = np.eye(4)
    matrix[0, 3] = 0.2
    steps = [("new", scene), ("lamp colour", scene.with_emission("light", lamp * (0.5, 1.0, 1.5))),
             ("albedo", scene.with_albedo("red-wall", (0.2, 0.7, 0.2))),
             ("lamp moved", scene.transformed_group("light", matrix))]
    for what, edited in steps:
        voxels = voxelize(edited, 16)
        blockers = encoding.occluders(edited, voxels)
        kept = field.predict(voxels, edited.sun, lo, hi, blockers, include_emitted=False)
        passes = field.passes_run
        fresh = field.predict(voxels, edited.sun, lo, hi, blockers, include_emitted=False, reuse=False)
        # the inputs agree to float32 rounding (1e-7); this random network's tail divides by small sums
        # at a few probes, which magnifies that to a few 1e-5 of the largest coefficient
        np.testing.assert_allclose(kept.coefficients, fresh.coefficients, rtol=1e-4,
                                   atol=4e-5 * np.abs(fresh.coefficients).max(), err_msg=what)
        assert np.array_equal(kept.valid, fresh.valid)
        assert passes == {"new": 3, "lamp colour": 0, "albedo": 3, "lamp moved": 3}[what], what


def test_neural_gi_recolours_the_voxels_of_a_colour_edit(exported):
    """The viewer's path: a colour edit keeps the voxels (recoloured by the faces' shares), a moved lamp
    voxelizes again; either way the probes are those of the edited scene from scratch. Which probes are
    valid is the geometry's: a colour edit keeps the first prediction's vote (a borderline vote that
    flipped with a colour cost the renderer a new lattice's weights), new geometry votes afresh."""
    _, path = exported
    gi = neural.NeuralGI(neural.NeuralField(path))
    scene = load("cornell")
    matrix = np.eye(4)
    matrix[2, 3] = 0.15
    lamp = scene.emission[scene.face_group == scene.group_index("light")][0]
    recoloured = scene.with_albedo("green-wall", (0.8, 0.8, 0.1))
    for what, edited in (("new", scene), ("albedo", recoloured),
                         ("lamp colour", recoloured.with_emission("light", lamp * (1.2, 0.6, 0.3))),
                         ("lamp moved", scene.transformed_group("light", matrix))):
        timings: dict = {}
        grid = gi.update(edited, include_emitted=True, timings=timings)
        assert ("voxelize" in timings) == (what in ("new", "lamp moved")), what
        assert gi.field.passes_run == (0 if what == "lamp colour" else 3), what
        fresh = neural.NeuralField(path).solve(edited, include_emitted=True)
        np.testing.assert_allclose(grid.coefficients, fresh.coefficients, rtol=1e-4,
                                   atol=1e-5 * np.abs(fresh.coefficients).max(), err_msg=what)
        first = grid if what == "new" else first
        assert np.array_equal(grid.valid, first.valid if what in ("albedo", "lamp colour") else fresh.valid), what


def test_mirror_augmentation_is_the_mirrored_scene():
    """Training mirrors encoded scenes instead of re-encoding them: the mirror of the encoding must be
    the encoding of the mirrored scene (x -> -x, winding reversed)."""
    scene = load("paper-test")
    flipped = Scene("mirrored", scene.vertices * np.array([-1.0, 1.0, 1.0]), scene.faces[:, ::-1],
                    scene.albedo, scene.emission, scene.face_group, scene.groups)
    a, b = encoded(scene), encoded(flipped)
    x = torch.from_numpy(a.inputs)
    y = torch.zeros(3, 18, 8, 8, 8)
    v = torch.zeros(3, 8, 8, 8)
    mirrored, _, _ = mirror(x, y, v, axis=0)
    np.testing.assert_allclose(b.scale, a.scale, rtol=1e-4)
    rest = np.ones(encoding.CHANNELS, bool)
    rest[encoding.BOUNCE] = rest[encoding.SEEN] = rest[encoding.OPEN] = False
    np.testing.assert_allclose(mirrored.numpy()[:, rest], b.inputs[:, rest], atol=2e-3)
    # the open share of a probe by a surface is a count of its rays, whose directions the mirror does not
    # keep: the same over the room, and the probes inside the boxes closed in both
    opened, ours_open = b.inputs[:, encoding.OPEN], mirrored.numpy()[:, encoding.OPEN]
    assert abs(ours_open.mean() - opened.mean()) < 0.01 * opened.mean()
    assert np.any(opened == 0.0) and np.all(ours_open[opened == 0.0] < 0.25)
    # the bounce's patches are merged on the voxel grid, which is not symmetric about the scene, so the
    # mirror is the mirrored scene's only in the mean (a wrong sign would be off by the whole coefficient)
    bounce = b.inputs[:, encoding.BOUNCE]
    difference = mirrored.numpy()[:, encoding.BOUNCE] - bounce
    assert np.sqrt(np.mean(difference ** 2)) < 0.03 * np.sqrt(np.mean(bounce ** 2))
    # the seen rays' directions are turned at random per probe, so the mirror's seen light is another
    # draw of the same noise: equal over the room, its signs those of the mirrored scene
    seen, ours = b.inputs[:, encoding.SEEN], mirrored.numpy()[:, encoding.SEEN]
    total = lambda values: values.sum(axis=(0, 2, 3, 4))   # noqa: E731  (9,) over the passes and probes
    assert np.all(np.abs(total(ours) - total(seen)) < 0.25 * total(np.abs(seen)))
    assert abs(total(ours)[0] - total(seen)[0]) < 0.05 * total(seen)[0]
    # where the seen filter stops: the links between neighbouring probes are segments the mirror maps
    # onto the mirrored scene's (a segment grazing a face may go either way)
    links = mirror_links(torch.from_numpy(a.links[None]), axis=0)[0].numpy()
    assert not b.links.all() and np.mean(links == b.links) > 0.995


def _wait_for_grid(gi, seconds: float = 600.0):
    import time

    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        changed, grid = gi.update()
        if changed and grid is not None:
            return grid
        time.sleep(0.01)
    raise AssertionError("no probes arrived")


def test_viewer_neural_source_updates_after_an_edit(exported):
    """GI source "neural": the network runs in the frame the voxels arrive; a recoloured wall gives
    new probes that differ where the wall's light goes."""
    from viewer.physical.gi import GISettings
    from viewer.ui.gi_sources import GIController

    _, path = exported
    gi = GIController(ctx=None, source="neural", settings=GISettings(voxels=16, probes=8), neural_model=path)
    gi.unavailable.pop("neural", None)
    gi.source = "neural"
    scene = load("cornell")
    try:
        gi.set_scene(scene, version=1)
        first = _wait_for_grid(gi)
        assert first.coefficients.shape == (8, 8, 8, 9, 3) and gi.status()[2] is None
        assert "ms network" in gi.status()[0]
        gi.set_scene(scene.with_albedo("red-wall", (0.05, 0.05, 0.8)), version=2)
        second = _wait_for_grid(gi)
        assert not np.allclose(first.coefficients, second.coefficients)
    finally:
        gi.close()


def test_viewer_falls_back_to_the_compute_solver_on_a_corrupt_model(exported, tmp_path):
    from viewer.physical.gi import GISettings
    from viewer.ui.gi_sources import GIController

    _, path = exported
    broken = tmp_path / "broken.onnx"
    broken.write_bytes(b"garbage")
    shutil.copy(path.with_suffix(".json"), broken.with_suffix(".json"))
    gi = GIController(ctx=None, source="compute", settings=GISettings(voxels=8, probes=4), neural_model=broken)
    gi.unavailable.pop("neural", None)
    gi.unavailable.pop("compute", None)
    try:
        gi.source = "off"
        gi.scene, gi._scene_version = load("cornell"), 1
        gi.set_source("neural")
        assert gi.source == "compute"
        line, _, error = gi.status()
        assert error is not None and "Neural model unusable" in error and "compute solver" in error
    finally:
        gi.close()


def test_a_colour_edit_keeps_the_geometrys_validity_vote(exported, monkeypatch):
    """A validity vote that flips with a colour (a borderline probe) is not passed on: for the same
    geometry (the same encoder and blockers) the first prediction's vote stays; new blockers vote again."""
    from dataclasses import replace

    from viewer.neural import field as field_module

    _, path = exported
    field = neural.NeuralField(path)
    scene = load("cornell")
    lo, hi = scene.bounds
    voxels = voxelize(scene, 16)
    blockers = encoding.occluders(scene, voxels)
    calls = []
    unpack = field_module.unpack

    def flipping(*args):   # every vote after the first differs at one probe
        grid = unpack(*args)
        calls.append(1)
        if len(calls) > 1:
            valid = grid.valid.copy()
            valid.flat[0] = not valid.flat[0]
            grid = replace(grid, valid=valid)
        return grid

    monkeypatch.setattr(field_module, "unpack", flipping)
    first = field.predict(voxels, scene.sun, lo, hi, blockers, include_emitted=False)
    recoloured = voxelize(scene.with_albedo("red-wall", (0.2, 0.7, 0.2)), 16)
    kept = field.predict(recoloured, scene.sun, lo, hi, blockers, include_emitted=False)
    assert np.array_equal(kept.valid, first.valid)
    again = field.predict(recoloured, scene.sun, lo, hi, encoding.occluders(scene, recoloured), include_emitted=False)
    assert again.valid.flat[0] != first.valid.flat[0]     # new blockers: a new geometry's own vote
