"""Bad input, and the exit status a command gives for it (docs/ARCHITECTURE.md, "Command line").

Each stage raises its own error for the bad input it finds (`viewer.scene.types.SceneError` for a scene
file, `viewer.bake.grid.BakedError` for a baked grid); `InputError` is for a bad command-line value. Every
command that runs on its own (`python -m viewer`, `python -m viewer.app`, `python -m viewer.bench.run`)
reports them through `exit_status`: one line on stderr, no traceback, exit status 2.

This module sits under the commands (viewer/cli.py, viewer/app.py, viewer/bench/run.py) and above the
stages whose errors it names: those never import it.
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import Callable

from viewer.bake.grid import BakedError
from viewer.scene.types import SceneError


class InputError(ValueError):
    """Bad input from the user: reported in one line with exit status 2. A ValueError, as the stages'
    own errors for bad input are."""


BAD_INPUT = (InputError, SceneError, BakedError)
"""The errors that mean "the user's input is wrong", not "the program is"."""


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """Help that ends each flag's text with its default, where it has one worth saying (not None, not a
    switch's False) and the text does not say it already."""

    def _get_help_string(self, action):
        text = action.help or ""
        default = action.default
        if (not text or "%(default)" in text or default in (None, False, argparse.SUPPRESS)
                or action.option_strings == [] and action.nargs not in ("?", "*")):
            return text
        return text + " (default: %(default)s)"


class ArgumentParser(argparse.ArgumentParser):
    """argparse whose errors are `InputError` (one line, exit status 2) instead of usage and SystemExit;
    its help shows the flags' defaults (DefaultsHelpFormatter)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", DefaultsHelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message):
        raise InputError(f"{self.prog}: {message}")


def one_line(text: str) -> str:
    """`text` as one printable line: newlines, terminal escapes and other control characters (which a file
    name or a string read from a file may hold) are shown escaped, so a message cannot print a forged
    second line or restyle the terminal."""
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


def exit_status(command: Callable[[], int], internal_errors: bool = True) -> int:
    """Run command and return its exit status: bad input (BAD_INPUT) is one line on stderr and 2.

    With internal_errors, any other exception is one line and 1 (its traceback only with VIEWER_DEBUG=1)
    and Ctrl+C is 130; without, they propagate (`python -m viewer.app` shows a crash's traceback)."""
    try:
        return command()
    except BAD_INPUT as exc:
        print(f"error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if not internal_errors:
            raise
        return 130
    except Exception as exc:  # an internal error: one line, and the traceback only when asked for
        if not internal_errors or os.environ.get("VIEWER_DEBUG"):
            raise
        print(f"internal error: {type(exc).__name__}: {one_line(str(exc))} (set VIEWER_DEBUG=1 for a traceback)",
              file=sys.stderr)
        return 1
