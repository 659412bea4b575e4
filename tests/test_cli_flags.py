"""The command line's flags come from the settings they set: every GI setting has a flag on `sample`,
`bake`, `capture` and the window whose help is the setting's docstring and shows its default; sizes and
cameras are parsed in one place; `capture` renders a typed CaptureRequest; the bench and training tools
share one parser."""

import ast
import dataclasses
from argparse import Namespace
from pathlib import Path

import numpy as np
import pytest

from viewer import cli, cli_parsing
from viewer.capture import capture_request
from viewer.cli_parsing import CAPTURE_SIZES, field_docs, gi_settings, parse_camera, parse_size
from viewer.errors import ArgumentParser, InputError
from viewer.gpu.render_settings import RenderSettings
from viewer.physical.gi import GISettings
from viewer.ui.options import add_arguments, options_from

ROOT = Path(__file__).resolve().parents[1]

GI_FLAGS = {"voxels": "--voxels", "probes": "--probes", "kernel": "--kernel", "bounces": "--bounces",
            "directions": "--directions", "gather_rays": "--gather-rays", "dering": "--dering",
            "invalid_backface_fraction": "--invalid-backface-fraction", "normal_mode": "--normals"}
"""Every GISettings field and its flag (the ones the command line had keep their spelling)."""


def command_parsers() -> dict:
    """`sample`, `bake`, `capture`, `view` of `python -m viewer`, and `python -m viewer.app`'s window."""
    parser = cli.build_parser()
    commands = next(a for a in parser._actions if a.dest == "command").choices
    window = ArgumentParser(prog="python -m viewer.app")
    add_arguments(window)
    return {**{name: commands[name] for name in ("sample", "bake", "capture", "view")}, "viewer.app": window}


def flag_of(parser, dest: str):
    return next(a for a in parser._actions if a.dest == dest)


def test_every_gi_setting_has_a_flag():
    assert set(GI_FLAGS) == {f.name for f in dataclasses.fields(GISettings)}


@pytest.mark.parametrize("command", ["sample", "bake", "capture", "view", "viewer.app"])
def test_each_gi_flag_is_documented_by_its_setting_with_its_default(command):
    parser = command_parsers()[command]
    docs = field_docs(GISettings)
    text = " ".join(parser.format_help().split())
    for name, flag in GI_FLAGS.items():
        action = flag_of(parser, name)
        default = getattr(GISettings(), name)
        assert action.option_strings == [flag] and action.default == default, (command, name)
        assert action.help % {"default": action.default} == f"{docs[name]} (default: {default})", (command, name)
        assert flag in text and f"(default: {default})" in text, (command, name)


def test_the_docstrings_read_are_the_fields_own():
    docs = field_docs(GISettings)
    assert docs["voxels"] == "N: voxels per axis."
    assert docs["normal_mode"] == "Voxel normals: `area` (area-weighted) or `paper` (eq. 3)."
    assert docs["probes"].startswith("M: probes per axis over the scene bounds. Measured against Mitsuba")
    assert set(docs) == set(GI_FLAGS)


def test_captures_render_flags_are_documented_by_render_settings():
    parser = command_parsers()["capture"]
    docs = field_docs(RenderSettings)
    for name, flag in {"exposure": "--exposure", "tonemap": "--tonemap", "light_samples": "--light-samples",
                       "voxel_color": "--voxel-color"}.items():
        action = flag_of(parser, name)
        default = getattr(RenderSettings(), name)
        assert action.option_strings == [flag] and action.default == default
        assert action.help % {"default": default} == f"{docs[name]} (default: {default})"


def test_the_gi_flags_set_every_field_and_the_old_spellings_still_work(tmp_path):
    base = ["sample", "cornell", "--points", "p.npy", "--out", "sh.npy"]
    old = cli.build_parser().parse_args(base + ["--voxels", "16", "--probes", "8", "--kernel", "paper",
                                                "--bounces", "7", "--directions", "64", "--dering", "0.5",
                                                "--normals", "paper"])
    assert gi_settings(old) == GISettings(voxels=16, probes=8, kernel="paper", bounces=7, directions=64,
                                          dering=0.5, normal_mode="paper")
    new = cli.build_parser().parse_args(base + ["--gather-rays", "32", "--invalid-backface-fraction", "1"])
    assert gi_settings(new) == GISettings(gather_rays=32, invalid_backface_fraction=1.0)
    assert gi_settings(cli.build_parser().parse_args(base)) == GISettings()
    window = options_from(Namespace(scene="cornell", gather_rays=128, normal_mode="paper"))
    assert gi_settings(window) == GISettings(gather_rays=128, normal_mode="paper")


@pytest.mark.parametrize("flags, message", [(["--voxels", "2"], "--voxels 2: must be between 4 and 256"),
                                            (["--dering", "3"], "--dering 3.0: must be between 0 and 1"),
                                            (["--gather-rays", "0"], "--gather-rays 0: must be between 1"),
                                            (["--invalid-backface-fraction", "2"],
                                             "--invalid-backface-fraction 2.0: must be between 0 and 1")])
def test_a_gi_flag_out_of_range_is_bad_input(flags, message):
    args = cli.build_parser().parse_args(["bake", "cornell", "--out", "g.npz", *flags])
    with pytest.raises(InputError, match=message.replace(".", r"\.")):
        gi_settings(args)


# ---- one parser of each kind --------------------------------------------------------------------------

def definitions(name: str) -> list[str]:
    """The files of viewer/ that define a function `name`, at any depth."""
    found = []
    for path in sorted((ROOT / "viewer").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name == name:
                found.append(str(path.relative_to(ROOT)))
    return found


@pytest.mark.parametrize("name", ["parse_size", "parse_camera", "gi_settings", "add_dataclass_flags"])
def test_each_parser_is_defined_once(name):
    assert definitions(name) == ["viewer/cli_parsing.py"]


def test_every_parser_is_the_one_that_exits_2_in_one_line():
    """No module builds a plain argparse parser: the commands' and the tools' parsers are
    viewer.errors.ArgumentParser (through viewer.cli_parsing.tool_parser for the tools)."""
    plain = []
    for path in sorted((ROOT / "viewer").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr == "ArgumentParser" and getattr(node.func.value, "id", "") == "argparse"):
                plain.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert plain == []


def test_sizes_keep_each_commands_limits():
    assert parse_size("64x64") == (64, 64) and parse_size("16384x64") == (16384, 64)
    with pytest.raises(InputError, match=r"--size '63x64': each side must be 64\.\.16384"):
        parse_size("63x64")
    assert parse_size("1x8192", *CAPTURE_SIZES) == (1, 8192)
    with pytest.raises(InputError, match=r"--size '8193x10': each side must be 1\.\.8192"):
        parse_size("8193x10", *CAPTURE_SIZES)
    with pytest.raises(InputError, match="expected WxH, e.g. 1280x720"):
        parse_size("big")
    assert cli.main(["view", "cornell", "--size", "10x10"]) == 2     # a window: 64 and up
    for refine in ("-1", "65", "many"):                               # images averaged: 0 (off) to 64
        assert cli.main(["view", "cornell", "--refine", refine]) == 2
    request = capture_request(Namespace(out="x.png", size="10x10"))   # a picture: 1 and up
    assert request.size == (10, 10)


def test_the_camera_parser_gives_origin_and_target():
    assert parse_camera("0,0,3.9,0,0,0") == ((0.0, 0.0, 3.9), (0.0, 0.0, 0.0))
    for text, message in [("1,2", "expected six numbers"), ("1,2,3,4,5,nan", "expected six numbers"),
                          ("1,1,1,1,1,1", "the same point")]:
        with pytest.raises(InputError, match=message):
            parse_camera(text)


def test_a_tools_bad_flag_is_one_line_and_exit_status_2(capsys):
    from viewer.bench import relight

    with pytest.raises(SystemExit) as exit_info:
        relight.main(["--repeats", "many"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "--repeats" in err[0]
    parser = cli_parsing.tool_parser("A tool.\n\nMore.", prog="tool")
    cli_parsing.add_scenes(parser)
    cli_parsing.add_repeats(parser, 3)
    cli_parsing.add_write(parser, "put the table into docs/X.md")
    cli_parsing.add_out(parser, Path("x.json"))
    assert parser.description == "A tool."
    assert vars(parser.parse_args([])) == {"scenes": ["cornell", "paper-test"], "repeats": 3, "write": False,
                                           "out": Path("x.json")}


# ---- capture's request ------------------------------------------------------------------------------------

CAPTURE = ["capture", "cornell", "--size", "64x48", "--msaa", "0", "--camera", "0,0,3.9,0,0,0", "--fov", "40",
           "--exposure", "0.5", "--tonemap", "reinhard"]


def test_capture_flags_become_a_typed_request(tmp_path):
    out = str(tmp_path / "shot.png")
    args = cli.build_parser().parse_args([*CAPTURE, "--out", out, "--gi", "compute", "--gather-rays", "32",
                                          "--normals", "paper", "--sun", "0,1,0,2,2,2"])
    request = capture_request(args)
    assert dataclasses.is_dataclass(request) and request.__dataclass_params__.frozen
    assert (request.out, request.scene, request.size, request.gi, request.view) == (out, "cornell", (64, 48),
                                                                                    "compute", "final")
    assert request.camera == ((0.0, 0.0, 3.9), (0.0, 0.0, 0.0)) and request.fov == 40.0 and request.msaa == 0
    assert request.render == RenderSettings(exposure=0.5, tonemap="reinhard")
    assert request.gi_settings == GISettings(gather_rays=32, normal_mode="paper")
    assert tuple(request.sun.direction) == (0.0, 1.0, 0.0) and request.model is None
    with pytest.raises(dataclasses.FrozenInstanceError):
        request.gi = "off"


@pytest.mark.parametrize("gi", ["off", "solver"])
def test_a_captured_request_is_the_picture_the_renderer_draws(tmp_path, gi):
    """The request from the flags, rendered, against the same picture drawn by hand: the same pixels."""
    from viewer import capture as captures
    from viewer.gpu.camera import look_at
    from viewer.gpu.offscreen import capture
    from viewer.physical import gi as solver
    from viewer.scene import load
    from PIL import Image

    out = tmp_path / f"{gi}.png"
    flags = ["--voxels", "8", "--probes", "4", "--directions", "64", "--gather-rays", "32"]
    args = cli.build_parser().parse_args([*CAPTURE, "--out", str(out), "--gi", gi, *flags])
    assert captures.run_capture(capture_request(args)) == 0
    scene = load("cornell")
    settings = GISettings(voxels=8, probes=4, directions=64, gather_rays=32)
    probes = solver.solve(scene, settings, include_emitted=False) if gi == "solver" else None
    expected = capture(scene, probes, size=(64, 48), camera=look_at((0, 0, 3.9), (0, 0, 0), 40.0),
                       settings=RenderSettings(exposure=0.5, tonemap="reinhard"), samples=0)
    np.testing.assert_array_equal(np.asarray(Image.open(out)), expected)


def test_the_window_without_a_display_captures_the_request_capture_would(monkeypatch):
    """The viewer's headless picture is `capture` with its scene, size, view and GI flags (the neural
    source falls back to the compute solver, as before)."""
    from viewer import app
    from viewer import capture as captures

    requests = []
    monkeypatch.setattr(captures, "run_capture", lambda request: requests.append(request) or 0)
    options = options_from(Namespace(scene="cornell", size="96x64", gi="neural", view="albedo", probes=8,
                                     normal_mode="paper", screenshot="shot.png"))
    assert app.render_headless(options) == 0
    args = cli.build_parser().parse_args(["capture", "cornell", "--out", "shot.png", "--size", "96x64", "--gi",
                                          "compute", "--view", "albedo", "--probes", "8", "--normals", "paper"])
    assert requests == [capture_request(args)]
