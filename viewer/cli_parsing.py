"""What every command line of the viewer parses alike: image sizes, cameras, the GI settings' flags (made
from the settings dataclasses, their docstrings the help), and the parser of the tools under viewer/bench
and viewer/training.

It sits beside viewer.errors, under the commands (viewer/cli.py, viewer/app.py, viewer/capture.py, the
tools), and never imports them. Cheap to import: no GL, imgui, Mitsuba or numba (the GI settings are
imported when their flags are made).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import math
import sys
import textwrap
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

from viewer.errors import ArgumentParser, InputError
from viewer.physical.work import MAX_PROBES, WorkError, check_work

if TYPE_CHECKING:
    from viewer.physical.gi import GISettings

# ---- values ---------------------------------------------------------------------------------------------

MAX_CAMERA_COORDINATE = 1e15
"""The largest camera coordinate (viewer.scene.types.MAX_COORDINATE for vertices): the view matrices are
float32."""
WINDOW_SIZES = (64, 16384)
"""The sides a window may have (`python -m viewer --size WxH`)."""
CAPTURE_SIZES = (1, 8192)
"""The sides a headless picture may have (`python -m viewer capture --size WxH`)."""


def parse_size(text, low: int = WINDOW_SIZES[0], high: int = WINDOW_SIZES[1],
               example: str = "1280x720") -> tuple[int, int]:
    """`--size WxH` -> (W, H), each side low..high; anything else is bad input (InputError).

    `example` is the size the message suggests when the text is not WxH."""
    try:
        width, height = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise InputError(f"--size {text!r}: expected WxH, e.g. {example}") from None
    if not (low <= width <= high and low <= height <= high):
        raise InputError(f"--size {text!r}: each side must be {low}..{high}")
    return width, height


MSAA_COUNTS = (0, 1, 2, 4, 8, 16)
"""The multisample counts OpenGL drivers offer (0: none); a count above the driver's own maximum is
lowered to it."""


def _whole_number(text, low: int, high: int) -> int:
    """An argparse type's body: a whole number from `low` (off) to `high`."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, not {text!r}") from None
    if not low <= value <= high:
        raise argparse.ArgumentTypeError(f"{value}: expected {low} (off) to {high}")
    return value


def supersample_count(text) -> int:
    """`--supersample N` (an argparse type): 1 (off) to MAX_SUPERSAMPLE."""
    return _whole_number(text, 1, MAX_SUPERSAMPLE)


MAX_SUPERSAMPLE = 32
"""32 x 32 = 1024 images a picture: Mitsuba's own sample count in the gallery."""


MAX_REFINE = 64
"""Images averaged into the window's still image at most (about a second of frames)."""


def refine_count(text) -> int:
    """`--refine N` (an argparse type): 0 (off) to MAX_REFINE; 1 is off too (one image)."""
    return _whole_number(text, 0, MAX_REFINE)


def msaa_count(text) -> int:
    """`--msaa N` (an argparse type): one of MSAA_COUNTS."""
    try:
        count = int(text)
    except ValueError:
        count = -1
    if count not in MSAA_COUNTS:
        raise argparse.ArgumentTypeError(f"{text!r} is not a multisample count: one of "
                                         f"{', '.join(map(str, MSAA_COUNTS))}")
    return count


def parse_camera(text: str) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """`--camera ox,oy,oz,tx,ty,tz` -> (origin, target): six finite numbers, two different points
    (viewer.gpu.camera.look_at turns them into a Camera); anything else is bad input (InputError)."""
    try:
        values = [float(v) for v in str(text).split(",")]
    except ValueError:
        values = []
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise InputError(f"--camera {text!r}: expected six numbers ox,oy,oz,tx,ty,tz")
    if max(abs(v) for v in values) > MAX_CAMERA_COORDINATE:
        raise InputError(f"--camera {text!r}: coordinates beyond +-{MAX_CAMERA_COORDINATE:.0e}, as for a scene's vertices")
    origin, target = tuple(values[:3]), tuple(values[3:])
    if math.dist(origin, target) < 1e-9:
        raise InputError(f"--camera {text!r}: the origin and the target are the same point")
    return origin, target


def camera_flags(origin, target, fov: float) -> str:
    """A view as capture's flags, `--camera ox,oy,oz,tx,ty,tz --fov F` (what `parse_camera` reads back): the
    window's C key gives it, so that a view found in the window can be captured."""
    numbers = ",".join(f"{float(v):.6g}" for v in (*origin, *target))
    return f"--camera {numbers} --fov {float(fov):.6g}"


NEGATIVE_VALUE_FLAGS = ("--camera", "--sun")
"""Flags whose value is a list of numbers that may start with a minus sign (`--camera -0.7,0.3,...`)."""


def joined_negative_values(argv: list[str], flags=NEGATIVE_VALUE_FLAGS) -> list[str]:
    """argv with `FLAG -0.7,0.3,...` written `FLAG=-0.7,0.3,...` for each of `flags`, so that argparse takes
    a value that starts with a minus sign for the flag's value, not for another flag."""
    out, i = [], 0
    while i < len(argv):
        arg = argv[i]
        following = argv[i + 1] if i + 1 < len(argv) else None
        if arg in flags and following is not None and _number_list(following):
            out.append(f"{arg}={following}")
            i += 2
            continue
        out.append(arg)
        i += 1
    return out


def _number_list(text: str) -> bool:
    """Whether text starts with '-' and reads as comma-separated numbers (`-0.7,0.3,0.9`, `-1`)."""
    if not text.startswith("-"):
        return False
    try:
        [float(v) for v in text.split(",")]
    except ValueError:
        return False
    return True


# ---- flags from settings dataclasses ----------------------------------------------------------------------

@lru_cache(maxsize=None)
def field_docs(cls) -> dict[str, str]:
    """A dataclass's field -> its docstring (the string literal under the field in the class body), with
    its lines joined into one paragraph."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    body = next(node for node in tree.body if isinstance(node, ast.ClassDef)).body
    docs = {}
    for node, after in zip(body, body[1:]):
        if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
                and isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant)
                and isinstance(after.value.value, str)):
            docs[node.target.id] = " ".join(inspect.cleandoc(after.value.value).split())
    return docs


def field_help(cls, name: str) -> str:
    """The help of the flag for field `name` of `cls`: its docstring and its default (argparse fills in
    %(default)s)."""
    return field_docs(cls)[name].replace("%", "%%") + " (default: %(default)s)"


def add_dataclass_flags(parser: argparse.ArgumentParser, cls, fields=None, names=None, choices=None,
                        metavars=None) -> None:
    """A flag for each of `fields` of the dataclass `cls` (default: all of them, in class order): named
    `names[field]` or the field's name in kebab case (`gather_rays` -> `--gather-rays`), stored under the
    field's name, with the field's default and type (or `choices[field]`), its docstring the help, and
    `metavars[field]` for its value in the usage line."""
    names, choices, metavars = names or {}, choices or {}, metavars or {}
    by_name = {f.name: f for f in dataclasses.fields(cls)}
    for name in fields if fields is not None else list(by_name):
        default = by_name[name].default
        if default is dataclasses.MISSING or isinstance(default, bool):
            raise TypeError(f"{cls.__name__}.{name}: only fields with a number or text default make flags")
        kind = {"choices": choices[name]} if name in choices else {"type": type(default)}
        if name in metavars:
            kind["metavar"] = metavars[name]
        parser.add_argument(names.get(name, "--" + name.replace("_", "-")), dest=name, default=default,
                            help=field_help(cls, name), **kind)


def dataclass_from_args(cls, args, fields=None):
    """An instance of `cls` with the values of args that name its `fields` (default: all of them; the
    class's defaults for those args lacks or leaves None)."""
    return cls(**{f.name: getattr(args, f.name) for f in dataclasses.fields(cls)
                  if (fields is None or f.name in fields) and getattr(args, f.name, None) is not None})


GI_FLAG_NAMES = {"normal_mode": "--normals"}
"""GI settings whose flag is not the field's name."""
GI_CHOICES = {"kernel": ("physical", "paper"), "normal_mode": ("area", "paper")}
GI_METAVARS = {"voxels": "N", "probes": "M", "bounces": "B", "directions": "D", "gather_rays": "R",
               "dering": "S", "invalid_backface_fraction": "F"}
GI_LIMITS = {"voxels": (4, 256), "probes": (2, MAX_PROBES), "bounces": (0, 100000), "directions": (16, 65536),
             "gather_rays": (1, 65536), "dering": (0.0, 1.0), "invalid_backface_fraction": (0.0, 1.0)}
"""The values a GI flag accepts, both ends included."""


def add_gi_flags(parser: argparse.ArgumentParser) -> None:
    """A flag for every GISettings field (`--voxels N`, `--probes M`, `--kernel`, `--bounces`,
    `--directions`, `--gather-rays`, `--dering`, `--invalid-backface-fraction`, `--normals`)."""
    from viewer.physical.gi import GISettings   # here: the tools' parsers need no numba

    add_dataclass_flags(parser, GISettings, names=GI_FLAG_NAMES, choices=GI_CHOICES, metavars=GI_METAVARS)


def gi_settings(args, size: tuple[int, int] | None = None, msaa: int = 1, frames: int = 1) -> GISettings:
    """The GISettings of the GI flags on args (defaults for the missing ones); a value out of range, or
    flags whose product (with a picture's `size`, `msaa` and animation `frames`) asks for more memory than a request may use
    (viewer.physical.work), is bad input (InputError)."""
    from viewer.physical.gi import GISettings

    settings = dataclass_from_args(GISettings, args)
    for name, (low, high) in GI_LIMITS.items():
        value = getattr(settings, name)
        if not low <= value <= high:
            flag = GI_FLAG_NAMES.get(name, "--" + name.replace("_", "-"))
            if isinstance(low, float):
                raise InputError(f"{flag} {value}: must be between {low:g} and {high:g}")
            raise InputError(f"{flag} {value}: must be between {low} and {high}")
    try:
        check_work(settings, size, msaa, frames)
    except WorkError as exc:
        raise InputError(str(exc)) from None
    return settings


# ---- the tools' parser -------------------------------------------------------------------------------------

class ToolParser(ArgumentParser):
    """The parser of a tool that runs on its own (`python -m viewer.bench.relight`, `python -m
    viewer.training.train` ...): bad flags are one line on stderr and exit status 2, as for
    `python -m viewer`."""

    def error(self, message):
        print(f"error: {self.prog}: {message}", file=sys.stderr)
        raise SystemExit(2)


def tool_parser(doc: str | None = None, prog: str | None = None, **kwargs) -> ToolParser:
    """A tool's parser; its description is the first line of `doc` (the tool module's docstring)."""
    if doc is not None:
        kwargs.setdefault("description", doc.splitlines()[0])
    return ToolParser(prog=prog, **kwargs)


def add_scenes(parser: argparse.ArgumentParser, default=("cornell", "paper-test"), flag: str | None = None,
               **kwargs) -> None:
    """The scenes a tool measures: positional SCENE ... (zero or more), or `flag` (one or more)."""
    if flag is None:
        parser.add_argument("scenes", nargs="*", default=list(default), **kwargs)
    else:
        parser.add_argument(flag, nargs="+", default=list(default), **kwargs)


def add_repeats(parser: argparse.ArgumentParser, default: int, **kwargs) -> None:
    """`--repeats N`: how often each measurement runs."""
    parser.add_argument("--repeats", type=int, default=default, **kwargs)


def add_write(parser: argparse.ArgumentParser, help: str) -> None:
    """`--write`: put the results into the docs (`help` says where)."""
    parser.add_argument("--write", action="store_true", help=help)


def add_out(parser: argparse.ArgumentParser, default=None, type=Path, **kwargs) -> None:
    """`--out`: where a tool writes its results."""
    parser.add_argument("--out", type=type, default=default, **kwargs)


def add_data(parser: argparse.ArgumentParser, default: Path = Path("data/gi-v2")) -> None:
    """`--data`: the dataset folder of the training tools."""
    parser.add_argument("--data", type=Path, default=default)
