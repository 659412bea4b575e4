"""What a new user meets on the command line: help that names the program, its defaults and the built-in
scenes; capture and the window on the same GI source; a camera whose x is negative; a scene nothing lights
said in one line by every command, and captured without the solve that could only give black; progress
lines on a terminal."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from viewer import cli, progress, sources
from viewer.cli_parsing import joined_negative_values
from viewer.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
ROOM_OBJ = "".join(f"v {x} {y} {z}\n" for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)) + (
    "f 1 3 4\nf 1 4 2\nf 5 6 8\nf 5 8 7\nf 1 2 6\nf 1 6 5\nf 3 7 8\nf 3 8 4\nf 1 5 7\nf 1 7 3\nf 2 4 8\nf 2 8 6\n")
"""A closed box with no emitter: nothing lights it."""


def run(*args, env=None):
    environment = {**os.environ, "PYTHONPATH": str(ROOT), **(env or {})}
    return subprocess.run([sys.executable, "-m", "viewer", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT, timeout=600, env=environment)


@pytest.fixture
def unlit(tmp_path):
    path = tmp_path / "unlit.obj"
    path.write_text(ROOM_OBJ)
    return path


# ---- help ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("argv0, name", [("/usr/bin/gi-viewer", "gi-viewer"), ("/x/viewer/__main__.py",
                                                                                "python -m viewer")])
def test_help_names_the_program_as_it_was_run(argv0, name):
    assert cli.program_name(argv0) == name
    assert cli.build_parser(prog=cli.program_name(argv0)).format_usage().startswith(f"usage: {name} ")


def test_help_shows_defaults_and_lists_the_builtin_scenes(monkeypatch):
    from viewer.scene import builtin_names

    monkeypatch.setenv("COLUMNS", "1000")   # no line breaks inside a name

    parser = cli.build_parser(prog="gi-viewer")
    for command in ("capture", "sample", "bake", "view"):
        text = " ".join(parser._subparsers._group_actions[0].choices[command].format_help().split())
        assert all(name in text for name in builtin_names()), (command, text)
    capture = " ".join(parser._subparsers._group_actions[0].choices["capture"].format_help().split())
    for default in ("(default: compute)", "(default: final)", "(default: 1280x720)", "(default: cornell)"):
        assert default in capture, default
    assert ".png, .jpg" in capture and ".npy" in capture
    assert "(default: None)" not in capture


def test_capture_and_the_window_start_on_the_same_gi_source():
    parser = cli.build_parser()
    assert parser.parse_args(["capture", "--out", "x.png"]).gi == sources.DEFAULT == "compute"
    assert parser.parse_args(["view"]).gi == sources.DEFAULT


# ---- negative numbers -------------------------------------------------------------------------------------

def test_a_camera_whose_x_is_negative_is_a_value_not_a_flag():
    argv = ["capture", "--camera", "-0.7,0.3,0.9,0,0,0", "--sun", "-1,1,0,2,2,2", "--out", "x.png"]
    joined = joined_negative_values(argv)
    assert joined == ["capture", "--camera=-0.7,0.3,0.9,0,0,0", "--sun=-1,1,0,2,2,2", "--out", "x.png"]
    args = cli.build_parser().parse_args(joined)
    assert args.camera == "-0.7,0.3,0.9,0,0,0" and args.sun == "-1,1,0,2,2,2"
    # what is not a list of numbers stays a flag: a missing value is still bad input
    assert joined_negative_values(["--camera", "--out", "x.png"]) == ["--camera", "--out", "x.png"]
    with pytest.raises(InputError):
        cli.build_parser().parse_args(["capture", "--camera", "--out", "x.png"])


def test_capture_takes_a_negative_camera_on_the_command_line(tmp_path):
    out = tmp_path / "left.png"
    result = run("capture", "cornell", "--gi", "off", "--size", "32x24", "--camera", "-0.7,0.3,3.5,0,0,0",
                 "--out", out)
    assert result.returncode == 0 and out.is_file(), result.stderr


# ---- unlit scenes -----------------------------------------------------------------------------------------

def test_capture_of_an_unlit_scene_says_so_writes_the_picture_and_skips_the_solve(tmp_path, unlit):
    out = tmp_path / "unlit.png"
    result = run("capture", unlit, "--size", "64x48", "--out", out)
    assert result.returncode == 0, result.stderr
    lines = result.stderr.strip().splitlines()
    warnings = [line for line in lines if "no emitter and no sun" in line]
    assert len(warnings) == 1 and "Ke" in warnings[0] and "emissiveFactor" in warnings[0] and "sun" in warnings[0]
    assert "not solved: nothing emits" in lines[-1]
    from PIL import Image

    assert np.asarray(Image.open(out)).shape == (48, 64, 3)


@pytest.mark.parametrize("command", ["sample", "bake"])
def test_sample_and_bake_of_an_unlit_scene_say_so(tmp_path, unlit, command):
    points = tmp_path / "points.npy"
    np.save(points, np.zeros((1, 3), np.float32))
    small = ["--voxels", "8", "--probes", "2", "--directions", "32"]
    if command == "sample":
        result = run("sample", unlit, "--points", points, "--out", tmp_path / "sh.npy", *small)
    else:
        result = run("bake", unlit, "--out", tmp_path / "grid.npz", *small)
    assert result.returncode == 0, result.stderr
    assert sum("no emitter and no sun" in line for line in result.stderr.splitlines()) == 1, result.stderr


def test_the_headless_window_of_an_unlit_scene_says_so(tmp_path, unlit):
    env = {k: "" for k in ("DISPLAY", "WAYLAND_DISPLAY")}
    result = run(unlit, "--size", "96x64", "--screenshot", tmp_path / "shot.png", env=env)
    assert result.returncode == 0, result.stderr
    assert sum("no emitter and no sun" in line for line in result.stderr.splitlines()) == 1, result.stderr


# ---- progress --------------------------------------------------------------------------------------------

def test_progress_lines_go_to_a_terminal_or_where_asked(monkeypatch, capsys):
    monkeypatch.setenv("GI_VIEWER_PROGRESS", "1")
    with progress.step("tracing"):
        pass
    assert capsys.readouterr().err == "viewer: tracing ...\n"
    monkeypatch.setenv("GI_VIEWER_PROGRESS", "0")
    progress.say("quiet")
    assert capsys.readouterr().err == ""


def test_each_kernel_compiled_is_said_once_the_first_saying_why():
    progress._announced.clear()
    first = progress.compile_message("viewer.rays.dda", "trace")
    assert first and "first run only" in first and "viewer.rays.dda.trace" in first
    assert progress.compile_message("viewer.rays.dda", "trace") is None
    assert progress.compile_message("viewer.gpu.final_gather", "_sum") == "compiling viewer.gpu.final_gather._sum"
    assert progress.compile_message("numpy.linalg", "solve") is None


def test_a_bar_in_a_log_is_lines_with_the_count_and_the_lines_that_must_stay(monkeypatch):
    """The dataset's and the benchmark's bar, written to a file: no carriage returns, the count of steps
    and their unit on every line, the results written through it kept whole, the last line 5/5."""
    import io

    monkeypatch.setattr(progress, "LOG_SECONDS", 0.0)
    log = io.StringIO()
    bar = progress.bar(5, "room", "rooms", done=2, stream=log)
    for i in range(3):
        bar.write(f"packed train/shard-{i:05d}.zip")
        bar.update(1)
    bar.close()
    lines = log.getvalue().splitlines()
    assert "\r" not in log.getvalue() and all(line.strip() for line in lines)
    assert [line for line in lines if line.startswith("packed")] == [f"packed train/shard-{i:05d}.zip" for i in range(3)]
    counts = [line for line in lines if not line.startswith("packed")]
    assert counts and all("room" in line for line in counts) and "5/5" in counts[-1], lines


def test_capture_says_what_it_is_doing_when_asked(tmp_path):
    result = run("capture", "cornell", "--gi", "off", "--size", "32x24", "--out", tmp_path / "c.png",
                 env={"GI_VIEWER_PROGRESS": "1"})
    assert result.returncode == 0, result.stderr
    assert "viewer: capture: rendering 32x24 ..." in result.stderr


def test_plural():
    assert progress.plural(1, "bounce") == "1 bounce" and progress.plural(3, "bounce") == "3 bounces"


# ---- small things ------------------------------------------------------------------------------------------

def test_a_captured_baked_grid_says_baked(tmp_path):
    grid, out = tmp_path / "grid.npz", tmp_path / "baked.png"
    small = ["--voxels", "8", "--probes", "4", "--directions", "32"]
    assert run("bake", "cornell", "--out", grid, *small).returncode == 0
    result = run("capture", grid, "--size", "32x24", "--out", out)
    assert result.returncode == 0, result.stderr
    assert "gi baked)" in result.stderr.strip().splitlines()[-1], result.stderr


def test_the_neural_warning_names_each_commands_flag():
    from viewer.neural.domain import warning

    line = warning(["a reason"])
    assert "--gi compute" in line and "--method solver" in line and "\n" not in line


def test_the_pictures_the_readme_writes_are_ignored_and_the_license_is_mit():
    ignored = subprocess.run(["git", "check-ignore", "-q", "cornell.png"], cwd=ROOT)
    assert ignored.returncode == 0
    assert "MIT License" in (ROOT / "LICENSE").read_text()
    assert 'license-files = ["LICENSE"]' in (ROOT / "pyproject.toml").read_text()


def test_a_view_copied_from_the_window_is_read_back_by_capture():
    from viewer.cli_parsing import camera_flags, parse_camera

    line = camera_flags((-0.7, 0.3, 3.5), (0.0, -0.1, 0.0), 42.5)
    assert line == "--camera -0.7,0.3,3.5,0,-0.1,0 --fov 42.5"
    args = cli.build_parser().parse_args(joined_negative_values(["capture", "--out", "x.png", *line.split()]))
    assert parse_camera(args.camera) == ((-0.7, 0.3, 3.5), (0.0, -0.1, 0.0)) and args.fov == 42.5


def test_a_turntable_is_an_animated_gif_turning_about_the_scene(tmp_path):
    from PIL import Image

    out = tmp_path / "turn.gif"
    result = run("capture", "cornell", "--gi", "off", "--size", "48x32", "--turntable", "8", "--out", out)
    assert result.returncode == 0, result.stderr
    gif = Image.open(out)
    assert gif.is_animated and gif.n_frames >= 4 and gif.size == (48, 32)
    first = np.asarray(gif.convert("RGB")).copy()
    gif.seek(1)
    assert np.abs(np.asarray(gif.convert("RGB")).astype(int) - first).max() > 30   # the view turned
    bad = run("capture", "cornell", "--turntable", "8", "--out", tmp_path / "turn.png")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "gif" in bad.stderr
