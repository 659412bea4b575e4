"""One place checks the memory a request asks for (viewer.physical.work): the product of the GI flags and
a picture's size, for `sample`, `capture`, `bake` and the window; what the defaults and the documented
examples ask for stays accepted, and what would run out of memory is one line and exit status 2 before
anything is loaded."""

import os
import subprocess
import sys
from argparse import Namespace
from pathlib import Path

import pytest

from viewer import cli
from viewer.capture import capture_request
from viewer.cli_parsing import gi_settings
from viewer.errors import InputError
from viewer.physical import work
from viewer.physical.gi import GISettings

ROOT = Path(__file__).resolve().parents[2]


def largest(settings=GISettings(), size=None, msaa=1) -> int:
    return max(stage.bytes for stage in work.stages(settings, size, msaa))


def test_the_defaults_and_the_documented_examples_are_well_within_the_limit(monkeypatch):
    monkeypatch.delenv(work.LIMIT_VARIABLE, raising=False)
    limit = work.memory_limit()
    assert limit == 4 << 30
    accepted = [GISettings(), GISettings(probes=32), GISettings(voxels=64), GISettings(voxels=48, probes=32),
                GISettings(directions=1024), GISettings(kernel="paper"), GISettings(voxels=128)]
    for settings in accepted:
        work.check_work(settings)
        work.check_work(settings, (1280, 720), 4)
    assert largest() < limit / 16
    work.check_work(GISettings(), (8192, 8192), 4)   # the largest capture --size, at the default --msaa


@pytest.mark.parametrize("flags, named", [
    ({"probes": 128, "directions": 65536}, "--probes 128 --directions 65536"),
    ({"voxels": 256}, "--voxels 256"),
    ({"voxels": 64, "kernel": "paper"}, "--voxels 64 --kernel paper"),
    ({"gather_rays": 65536}, "--gather-rays 65536"),
])
def test_a_product_of_flags_past_the_limit_is_refused_naming_them_and_the_memory(flags, named, monkeypatch):
    monkeypatch.delenv(work.LIMIT_VARIABLE, raising=False)
    with pytest.raises(work.WorkError) as refused:
        work.check_work(GISettings(**flags))
    message = str(refused.value)
    assert named in message and "GiB" in message and "4.0 GiB" in message and "\n" not in message


def test_the_limit_can_be_raised_and_a_bad_limit_is_refused(monkeypatch):
    monkeypatch.setenv(work.LIMIT_VARIABLE, "64")
    work.check_work(GISettings(voxels=256))
    for bad in ("lots", "-1", "nan", "0"):
        monkeypatch.setenv(work.LIMIT_VARIABLE, bad)
        with pytest.raises(work.WorkError, match=work.LIMIT_VARIABLE):
            work.check_work(GISettings())


def test_every_command_asks_the_same_check(monkeypatch):
    monkeypatch.delenv(work.LIMIT_VARIABLE, raising=False)
    parser = cli.build_parser()
    for command in (["sample", "cornell", "--points", "p.npy", "--out", "o.npy"], ["bake", "cornell", "--out", "o.npz"],
                    ["capture", "--out", "o.png"]):
        args = parser.parse_args(command + ["--probes", "128", "--directions", "65536"])
        with pytest.raises(InputError, match="--probes 128 --directions 65536"):
            (capture_request if command[0] == "capture" else gi_settings)(args)
    big_picture = parser.parse_args(["capture", "--out", "o.png", "--size", "8192x8192", "--msaa", "16"])
    with pytest.raises(InputError, match="--size 8192x8192 --msaa 16: the picture"):
        capture_request(big_picture)
    window = Namespace(voxels=32, size="16384x16384")
    with pytest.raises(InputError, match="--size 16384x16384"):
        gi_settings(window, size=(16384, 16384))


def run(*args, env=None):
    environment = dict(os.environ, PYTHONPATH=str(ROOT), DISPLAY="", WAYLAND_DISPLAY="", **(env or {}))
    environment.pop(work.LIMIT_VARIABLE, None)
    return subprocess.run([sys.executable, "-m", "viewer", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT, env=environment, timeout=600)


def test_the_command_line_refuses_too_much_work_at_once_in_one_line(tmp_path):
    """Before this check `--probes 128 --directions 65536` ended in a MemoryError and `--voxels 256` ran
    past 300 s at 7.6 GB: now each is refused before the scene is read."""
    cases = [["sample", "cornell", "--points", tmp_path / "p.npy", "--out", tmp_path / "o.npy", "--probes", "128",
              "--directions", "65536"],
             ["bake", "cornell", "--out", tmp_path / "o.npz", "--voxels", "256"],
             ["capture", "--out", tmp_path / "o.png", "--size", "8192x8192", "--msaa", "16"],
             ["--voxels", "256"]]   # the window (here headless: no display)
    for args in cases:
        result = run(*args)
        assert result.returncode == 2, (args, result.stderr)
        lines = result.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith("error:") and "GiB" in lines[0], (args, result.stderr)
    assert not list(tmp_path.iterdir())


def test_the_window_keeps_its_settings_when_a_panel_edit_would_take_too_much(monkeypatch):
    from viewer.ui.gi_sources import GIController

    monkeypatch.delenv(work.LIMIT_VARIABLE, raising=False)
    start = GISettings(probes=2, directions=65536)   # 8 probes x 65536 directions: 8 MiB of rays
    gi = GIController(ctx=None, source="off", settings=start)
    gi.set_settings(probes=32)                       # 32^3 x 65536: 32 GiB
    assert gi.settings == start and "--probes 32 --directions 65536" in gi.refused
    gi.set_settings(kernel="paper", voxels=64)       # the all-pairs kernel on 64^3 voxels
    assert gi.settings == start and "--kernel paper" in gi.refused
    gi.set_settings(probes=4)
    assert gi.settings.probes == 4 and gi.refused is None


def test_a_turntable_keeps_every_frame_and_is_counted_so(monkeypatch):
    monkeypatch.delenv(work.LIMIT_VARIABLE, raising=False)
    work.check_work(GISettings(), (1280, 720), 4, frames=120)
    with pytest.raises(work.WorkError, match="--size 8192x8192 --turntable 720: the frames"):
        work.check_work(GISettings(), (8192, 8192), 4, frames=720)
    args = cli.build_parser().parse_args(["capture", "--out", "t.gif", "--size", "4096x4096", "--turntable", "720"])
    with pytest.raises(InputError, match="--turntable 720"):
        capture_request(args)
