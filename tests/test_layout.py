"""The package's shape: what may import what, read from the source with `ast` (nothing is imported).

- no module reaches into another module's private (underscore) names: what is shared is public;
- no package imports a package above it in the pipeline (RANKS below), and bench and training, the two
  tools at the top, do not import each other: what both need lives in viewer/evaluation/;
- no import circle between modules, whether the imports are at module level or inside a function;
- no file under viewer/ over MAX_LINES lines.

Every offender is reported with its file and line. `python tests/test_layout.py` prints them all.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "viewer"
MAX_LINES = 400

RANKS = {
    # the package itself (viewer/__init__.py), where the data files are, the progress lines
    "viewer": 0, "resources": 0, "progress": 0,
    "wake": 0,                        # a worker's result wakes the window's frame loop
    "output": 0,                      # files written whole, where the user said
    "threads": 0,                     # how many cores a compiled pass uses
    "scene": 1,                       # the Scene type and everything that makes one
    "rays": 2,                        # voxels and the compiled ray kernels
    "probes": 3,                      # the ProbeGrid type, SH, the surface weights
    "physical": 4, "neural": 4, "reference": 4,  # the three producers of probes
    "bake": 5,                        # a converged grid written for other tools, and read back
    "evaluation": 5,                  # the measures bench and training share (error, test points, truth)
    "errors": 6, "cli_parsing": 6,    # bad input and its exit status; what every command line parses alike
    "gpu": 7,                         # the renderer, the compute shaders, headless capture
    "memory": 8,                      # resident memory and live GL objects
    "ui": 9, "capture": 9, "sources": 9,  # the window's pieces, the headless capture, the GI sources
    "app": 10,                        # the window; without a display it falls back to capture
    "bench": 11, "training": 11,      # the tools: measure everything, train the network
    "cli": 12,                        # the command line (`python -m viewer bench` too): nothing imports it
    "__main__": 13,
}
"""A package may import its own rank and below. The ranks follow the pipeline: a scene is voxelized,
traced, lit into probes, rendered, shown; the tools and the command line use all of it."""

APART = {("bench", "training"), ("training", "bench")}
"""Packages of one rank that must not import each other."""

ACROSS = {
    ("viewer.bench.neural", "viewer.training.export"): "the ProbeNet size table (`--configs`) exports "
                                                         "random-weight networks with training's torch model",
    ("viewer.bench.neural", "viewer.training.models"): "the same: the torch ProbeNet of each size",
    ("viewer.bench.stability.distance", "viewer.training.samples"): "the out-of-distribution study measures a "
                                                                    "scene's distance to training's encoded split",
}
"""The only imports from bench into training, each inside the function that needs it (torch and the dataset
are optional there), with why. Training imports nothing of bench."""


@dataclass(frozen=True)
class Module:
    name: str
    path: Path
    is_package: bool

    @property
    def where(self) -> str:
        return str(self.path.relative_to(ROOT))


@dataclass(frozen=True)
class Import:
    source: str       # the importing module
    target: str       # the module imported (a module, or the package a name is imported from)
    names: tuple      # the names taken from target ("from target import a, b"); () for "import target"
    line: int


@cache
def modules() -> dict[str, Module]:
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        if is_package:
            parts = parts[:-1]
        found[".".join(parts)] = Module(".".join(parts), path, is_package)
    return found


@cache
def tree(name: str) -> ast.Module:
    return ast.parse(modules()[name].path.read_text(), filename=str(modules()[name].path))


def absolute(module: Module, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    base = module.name.split(".") if module.is_package else module.name.split(".")[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def is_main_block(node: ast.AST) -> bool:
    """`if __name__ == "__main__":`: what runs when the module is a program, not what importing it runs."""
    test = getattr(node, "test", None)
    return (isinstance(node, ast.If) and isinstance(test, ast.Compare) and isinstance(test.left, ast.Name)
            and test.left.id == "__name__" and len(test.comparators) == 1
            and isinstance(test.comparators[0], ast.Constant) and test.comparators[0].value == "__main__")


def walk(root: ast.AST):
    """ast.walk, leaving out `__main__` blocks: a module run as a program may import the command that
    uses it (viewer/training/dataset.py runs viewer/training/dataset_cli.py)."""
    for node in ast.iter_child_nodes(root):
        if is_main_block(node):
            continue
        yield node
        yield from walk(node)


@cache
def imports(name: str) -> tuple[Import, ...]:
    """Every import of a viewer module in module `name`, at any depth (function-level ones too).
    `from package import module` counts as an import of that module."""
    module, known, found = modules()[name], modules(), []
    for node in walk(tree(name)):
        if isinstance(node, ast.Import):
            found += [Import(name, alias.name, (), node.lineno) for alias in node.names
                      if alias.name.split(".")[0] == "viewer"]
        elif isinstance(node, ast.ImportFrom):
            base = absolute(module, node)
            if base.split(".")[0] != "viewer":
                continue
            names = []
            for alias in node.names:
                if f"{base}.{alias.name}" in known:
                    found.append(Import(name, f"{base}.{alias.name}", (), node.lineno))
                else:
                    names.append(alias.name)
            if names:
                found.append(Import(name, base, tuple(names), node.lineno))
    return tuple(found)


def is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def package_of(name: str) -> str:
    parts = name.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def private_uses() -> list[str]:
    """`from viewer.x import _name`, and `module._name` on a viewer module bound by an import."""
    found = []
    for name, module in modules().items():
        bound = {}  # local name -> the viewer module it is bound to (dotted prefixes for plain imports)
        for imp in imports(name):
            if imp.target != name:
                found += [f"{module.where}:{imp.line}: imports {imp.target}.{n}"
                          for n in imp.names if is_private(n)]
        for node in ast.walk(tree(name)):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.split(".")[0] == "viewer":
                        bound[alias.asname or "viewer"] = alias.name if alias.asname else "viewer"
            elif isinstance(node, ast.ImportFrom):
                base = absolute(module, node)
                for alias in node.names:
                    if f"{base}.{alias.name}" in modules():
                        bound[alias.asname or alias.name] = f"{base}.{alias.name}"
        for node in ast.walk(tree(name)):
            if not (isinstance(node, ast.Attribute) and is_private(node.attr)):
                continue
            chain, value = [], node.value
            while isinstance(value, ast.Attribute):
                chain.insert(0, value.attr)
                value = value.value
            if not (isinstance(value, ast.Name) and value.id in bound):
                continue
            target = ".".join([bound[value.id]] + chain)
            if target in modules() and target != name:
                found.append(f"{module.where}:{node.lineno}: uses {target}.{node.attr}")
    return found


def upward_imports() -> list[str]:
    found = []
    for name, module in modules().items():
        here = package_of(name)
        for imp in imports(name):
            there = package_of(imp.target)
            if here == there:
                continue
            if here not in RANKS or there not in RANKS:
                unranked = here if here not in RANKS else there
                found.append(f"{module.where}:{imp.line}: package {unranked!r} has no rank in RANKS")
            elif RANKS[there] > RANKS[here] or ((here, there) in APART and (name, imp.target) not in ACROSS):
                found.append(f"{module.where}:{imp.line}: {here} (rank {RANKS[here]}) imports "
                             f"{imp.target} ({there}, rank {RANKS[there]})")
    return found


def import_circles() -> list[str]:
    """Every strongly connected set of modules (Tarjan), with the imports that close it."""
    known = modules()
    graph = {name: sorted({imp.target for imp in imports(name) if imp.target in known and imp.target != name})
             for name in known}
    index, low, stack, on_stack, circles = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for after in graph[node]:
            if after not in index:
                visit(after)
                low[node] = min(low[node], low[after])
            elif after in on_stack:
                low[node] = min(low[node], index[after])
        if low[node] == index[node]:
            members = set()
            while True:
                member = stack.pop()
                on_stack.discard(member)
                members.add(member)
                if member == node:
                    break
            if len(members) > 1:
                circles.append(members)

    for name in known:
        if name not in index:
            visit(name)
    found = []
    for members in circles:
        edges = [f"{known[imp.source].where}:{imp.line} -> {imp.target}"
                 for source in sorted(members) for imp in imports(source) if imp.target in members
                 and imp.target != source]
        found.append(f"circle {', '.join(sorted(members))}: " + "; ".join(edges))
    return found


def long_files() -> list[str]:
    return [f"{module.where}:{MAX_LINES + 1}: {count} lines (at most {MAX_LINES})"
            for module in modules().values()
            if (count := len(module.path.read_text().splitlines())) > MAX_LINES]


def report(found: list[str]) -> str:
    return f"{len(found)} offender(s):\n" + "\n".join(found)


def test_no_private_names_across_modules():
    found = private_uses()
    assert not found, report(found)


def test_no_upward_imports():
    found = upward_imports()
    assert not found, report(found)


def test_no_import_circles():
    found = import_circles()
    assert not found, report(found)


def test_no_long_files():
    found = long_files()
    assert not found, report(found)


def test_every_package_is_in_the_wheel():
    """pyproject.toml lists the packages by name: a new package folder must be listed to be installed."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    missing = sorted(m.name for m in modules().values() if m.is_package and m.name not in listed)
    assert not missing, f"pyproject.toml [tool.setuptools] packages lacks {', '.join(missing)}"


def test_the_checks_see_the_package():
    """The scan reads the real tree: the ranked packages exist and the kernels' imports are found."""
    assert len(modules()) > 100
    assert any(imp.target == "viewer.rays.dda" for imp in imports("viewer.physical.geometry"))
    assert {package_of(name) for name in modules()} <= set(RANKS)


if __name__ == "__main__":
    for title, check in [("private names", private_uses), ("upward imports", upward_imports),
                         ("import circles", import_circles), ("long files", long_files)]:
        found = check()
        print(f"== {title}: {len(found)}")
        print("\n".join(found))
