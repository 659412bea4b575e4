"""Shader programs from files under `shaders/`: one .glsl file per program, stages as sections.

A program file holds every stage it needs, each under `#if defined VERTEX_SHADER`, `FRAGMENT_SHADER`,
`GEOMETRY_SHADER` or `COMPUTE_SHADER` (the moderngl-window layout). Compiling a stage prepends
`#version`, `#define <STAGE>_SHADER` and the defines passed from Python, and replaces every
`#include "name.glsl"` by that file (once per stage, resolved next to the including file, then in the
shader directory). `#line` directives give each file its own GLSL source-string number and also
encode that number in the line numbers (line + file * LINE_STRIDE), because Mesa reports some errors
with source string 0 whatever the file; a compiler message `2:200014(3): error` is translated back
to `sh.glsl:14`.

A compile or link error raises `ShaderError` with the file names and lines. `ProgramLibrary.reload`
recompiles every program and keeps the old one wherever the new source fails, so a live-editing viewer
keeps drawing.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import moderngl

from viewer.resources import SHADERS

GLSL_VERSION = "#version 430 core"
STAGES = ("VERTEX_SHADER", "GEOMETRY_SHADER", "FRAGMENT_SHADER", "COMPUTE_SHADER")
_KEYWORDS = {"VERTEX_SHADER": "vertex_shader", "GEOMETRY_SHADER": "geometry_shader",
             "FRAGMENT_SHADER": "fragment_shader"}
_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$')
_VERSION = re.compile(r"^\s*#\s*version\b")
_MESSAGE = re.compile(r"^(\d+):(\d+)\((\d+)\):\s*(.*)$")   # Mesa: source:line(column): text
LINE_STRIDE = 100000
"""#line numbers are line + file index * LINE_STRIDE (no shader file is that long)."""


class ShaderError(RuntimeError):
    """A shader file that cannot be read, preprocessed, compiled or linked. The message names the file
    and line of every error the compiler reported."""


@dataclass
class Source:
    """One preprocessed stage: the GLSL text and the file behind each GLSL source-string number."""

    text: str
    files: list[Path] = field(default_factory=list)

    def locate(self, log: str) -> str:
        """Rewrite a compiler log's `N:line(col): msg` lines as `file.glsl:line: msg`."""
        out = []
        for line in log.splitlines():
            match = _MESSAGE.match(line.strip())
            file, number = divmod(int(match.group(2)), LINE_STRIDE) if match else (-1, 0)
            if match and 0 <= file < len(self.files):
                out.append(f"{_display(self.files[file])}:{number}: {match.group(4)}")
            elif line.strip() and not set(line.strip()) <= {"="}:
                out.append(line.strip())
        return "\n".join(out)


def _display(path: Path) -> str:
    try:
        return str(path.relative_to(SHADERS.parent))
    except ValueError:
        return str(path)


def format_define(name: str, value) -> str:
    if value is True:
        value = 1
    elif value is False:
        value = 0
    return f"#define {name} {value}".rstrip()


def preprocess(path: Path | str, stage: str, defines: dict | None = None,
               search: tuple[Path, ...] = (SHADERS,)) -> Source:
    """The GLSL text of one stage of a program file, with includes expanded and `#line` directives."""
    if stage not in STAGES:
        raise ValueError(f"unknown shader stage {stage!r}; one of {STAGES}")
    path = Path(path)
    source = Source("")
    header = [GLSL_VERSION, f"#define {stage}"]
    header += [format_define(k, v) for k, v in (defines or {}).items()]
    body = _expand(path, source, search, seen=set(), chain=())
    source.text = "\n".join(header) + "\n" + body
    return source


def _expand(path: Path, source: Source, search: tuple[Path, ...], seen: set, chain: tuple) -> str:
    path = path.resolve()
    if path in chain:
        raise ShaderError(f"{_display(path)}: #include cycle ({' -> '.join(_display(p) for p in chain + (path,))})")
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise ShaderError(f"{_display(path)}: cannot read shader ({exc.strerror or exc})") from None
    number = len(source.files)
    source.files.append(path)
    out = [_line_directive(1, number)]
    for index, line in enumerate(lines, start=1):
        match = _INCLUDE.match(line)
        if _VERSION.match(line):
            out.append("")  # the version comes first in the header; keep the line count
        elif match:
            included = _find(match.group(1), path.parent, search)
            if included is None:
                raise ShaderError(f"{_display(path)}:{index}: #include \"{match.group(1)}\": no such file "
                                  f"next to it or in {', '.join(_display(s) for s in search)}")
            if included.resolve() not in seen:   # every include once per stage (an implicit guard)
                seen.add(included.resolve())
                out.append(_expand(included, source, search, seen, chain + (path,)))
            out.append(_line_directive(index + 1, number))
        else:
            out.append(line)
    return "\n".join(out)


def _line_directive(line: int, file: int) -> str:
    return f"#line {line + file * LINE_STRIDE} {file}"


def _find(name: str, here: Path, search: tuple[Path, ...]) -> Path | None:
    for folder in (here, *search):
        candidate = folder / name
        if candidate.is_file():
            return candidate
    return None


def stages_in(path: Path) -> list[str]:
    """The stages a program file defines (those named in an `#if defined X_SHADER` or `#ifdef X_SHADER`)."""
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise ShaderError(f"{_display(Path(path))}: cannot read shader ({exc.strerror or exc})") from None
    return [s for s in STAGES if re.search(rf"\b{s}\b", text)]


def compile_program(ctx: moderngl.Context, path: Path | str, defines: dict | None = None,
                    search: tuple[Path, ...] = (SHADERS,)):
    """A moderngl Program (or ComputeShader, for a file with a COMPUTE_SHADER section) from one file."""
    path = Path(path)
    stages = stages_in(path)
    if not stages:
        raise ShaderError(f"{_display(path)}: no `#if defined VERTEX_SHADER/FRAGMENT_SHADER/COMPUTE_SHADER` "
                          f"section")
    sources = {stage: preprocess(path, stage, defines, search) for stage in stages}
    try:
        if "COMPUTE_SHADER" in sources:
            return ctx.compute_shader(sources["COMPUTE_SHADER"].text)
        return ctx.program(**{_KEYWORDS[s]: src.text for s, src in sources.items()})
    except moderngl.Error as exc:
        raise ShaderError(_explain(path, str(exc), sources)) from None


def _explain(path: Path, message: str, sources: dict[str, Source]) -> str:
    """moderngl's 'GLSL Compiler failed / vertex_shader / ===== / 0:3(5): error' as readable lines."""
    stage = next((s for s in sources if _KEYWORDS.get(s, "compute_shader") in message), None)
    source = sources.get(stage) or next(iter(sources.values()))
    what = "link" if "Linker" in message else f"compile ({stage.lower().replace('_', ' ')})" if stage else "compile"
    details = source.locate(message.replace("GLSL Compiler failed", "").replace("GLSL Linker failed", ""))
    details = "\n".join(line for line in details.splitlines()
                        if line not in ("vertex_shader", "fragment_shader", "geometry_shader", "compute_shader",
                                        "Program"))
    return f"{_display(path)}: shader {what} failed:\n{details}"


class ProgramLibrary:
    """Compiled programs by (file, defines), with hot reload that keeps the last good program."""

    def __init__(self, ctx: moderngl.Context, directory: Path | str = SHADERS):
        self.ctx = ctx
        self.directory = Path(directory)
        self._programs: dict[tuple, object] = {}

    def get(self, name: str, **defines):
        """The program compiled from `<directory>/<name>.glsl` with these defines (compiled on first use;
        raises ShaderError when that fails)."""
        key = (name, tuple(sorted(defines.items())))
        if key not in self._programs:
            self._programs[key] = self._compile(name, defines)
        return self._programs[key]

    def _compile(self, name: str, defines: dict):
        return compile_program(self.ctx, self.directory / f"{name}.glsl", defines,
                               search=(self.directory,))

    def reload(self) -> None:
        """Recompile every program from its file. Programs that compile are replaced; for the others
        the old program stays in use, and a ShaderError lists what failed."""
        errors = []
        for key in list(self._programs):
            name, defines = key
            try:
                program = self._compile(name, dict(defines))
            except ShaderError as exc:
                if str(exc) not in errors:  # variants of one file (other defines) fail alike
                    errors.append(str(exc))
                continue
            self._programs[key].release()
            self._programs[key] = program
        if errors:
            raise ShaderError("\n".join(errors))

    def release(self) -> None:
        for program in self._programs.values():
            program.release()
        self._programs.clear()


def shared_library(ctx: moderngl.Context, directory: Path | str = SHADERS) -> ProgramLibrary:
    """The one ProgramLibrary of `ctx` for the programs under `directory`, for code that makes a new
    solver per solve (compute_solver.solve_probes, the command line, the benchmarks): each program is
    compiled once per context and reused by every later solve. A library per solve compiled all of them
    again each time and dropped them unreleased, about 3 MB a solve that llvmpipe never got back
    (docs/STABILITY.md). The library is kept on the context itself, so it goes when the context goes."""
    libraries = ctx.__dict__.setdefault("_viewer_program_libraries", {})
    key = Path(directory).resolve()
    if key not in libraries:
        libraries[key] = ProgramLibrary(ctx, directory)
    return libraries[key]


def set_uniforms(program, **values) -> None:
    """Set the uniforms a program uses; names the compiler optimised away are skipped."""
    for name, value in values.items():
        if name in program:
            uniform = program[name]
            if isinstance(value, (bytes, bytearray)):
                uniform.write(value)
            else:
                uniform.value = value
