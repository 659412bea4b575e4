"""The viewer's command-line flags (`python -m viewer [view] ...`, `python -m viewer.app ...`) and their
defaults (the window's size is parsed by viewer.cli_parsing.parse_size). Cheap to import: no GL or imgui
(viewer/cli.py adds these flags to its `view` command)."""

from __future__ import annotations

import argparse
from types import SimpleNamespace

from viewer import sources
from viewer.cli_parsing import add_gi_flags, msaa_count, refine_count
from viewer.errors import ArgumentParser

VIEW_CHOICES = ("final", "direct", "indirect", "albedo", "normals", "voxels", "probes")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The viewer's own flags (cheap to call: no GL or imgui import)."""
    parser.add_argument("--gi", choices=sources.chosen_by_name(), default=sources.DEFAULT,
                        help="indirect light source at start (compute: the compute-shader solver)")
    parser.add_argument("--view", choices=VIEW_CHOICES, default="final", help="what the view shows at start")
    parser.add_argument("--size", default="1280x720", metavar="WxH", help="window size (default: %(default)s)")
    parser.add_argument("--refine", type=refine_count, default=8, metavar="N",
                        help="edge anti-aliasing: once the view rests, N images at subpixel offsets are averaged "
                             "into the still image, one a frame (0: off; default: %(default)s)")
    parser.add_argument("--msaa", type=msaa_count, default=0, metavar="N",
                        help="multisample the still image instead (2, 4 or 8 samples; each still frame then "
                             "costs 3-4 times as much on a software GL; default: %(default)s, off)")
    add_gi_flags(parser)
    parser.add_argument("--screenshot", help="save the rendered image (no panels) here once it has settled "
                                             "(GI done, full resolution), then quit")
    parser.add_argument("--screenshot-window", help="with --screenshot: also save the whole window, panels "
                                                    "included")
    parser.add_argument("--frames", type=int, help="quit after this many frames")
    parser.add_argument("--quit-after", type=float, help="quit after this many seconds")
    parser.add_argument("--hide-panel", action="store_true", help="start with the settings panel hidden (Tab)")
    parser.add_argument("--bench", type=int, metavar="FRAMES",
                        help="once the picture has settled (GI done), draw the scene this many more frames at "
                             "full resolution, print their CPU and GPU ms, and quit")
    parser.add_argument("--redraw-always", action="store_true",
                        help="draw the scene every frame, not only when it changes (for timing)")
    parser.add_argument("--stats", help="write a JSON summary (frame times, scene, camera, messages) here at "
                                        "exit and after every screenshot")
    parser.add_argument("--shader-dir", help="load shaders from this folder instead of shaders/")
    parser.add_argument("--resources", nargs="?", const="held", choices=("held", "resident"),
                        help="log memory and live GL objects whenever the picture has settled after the start, "
                             "a load or a failed load (python -m viewer.bench.soak reads them): resident memory "
                             "after the C heap's free memory is handed back (held, the default) or as it is")


def options_from(args) -> SimpleNamespace:
    """The command line's namespace with every viewer flag present (defaults for missing ones)."""
    parser = ArgumentParser(add_help=False)
    parser.add_argument("scene", nargs="?", default="cornell")
    add_arguments(parser)
    options = vars(parser.parse_args([]))
    options.update({k: v for k, v in vars(args).items() if v is not None})
    return SimpleNamespace(**options)
