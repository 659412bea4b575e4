"""Where the viewer's data files are: the shader files, the shipped models and the built-in scenes.

The repository keeps them in the top-level folders `shaders/`, `models/` and `assets/scenes/` (the layout
of docs/ARCHITECTURE.md), which is where a checkout finds them: running from source, or installed with
`pip install -e .`. A wheel cannot reach outside its package, so pyproject.toml maps the same folders
into it as `viewer/_data/shaders`, `viewer/_data/models` and `viewer/_data/scenes`, found here through
importlib.resources. Every module that reads a data file asks this one.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

CHECKOUT = Path(__file__).resolve().parent.parent
"""The repository root, when the package runs from a checkout."""
LAYOUT = {"shaders": "shaders", "models": "models", "scenes": "assets/scenes"}
"""Data folder -> where the repository keeps it (the wheel keeps it as viewer/_data/<folder>)."""


def data_folder(name: str) -> Path:
    """The folder of one kind of data (`shaders`, `models` or `scenes`): the copy inside an installed
    wheel when there is one, else the repository's own."""
    if name not in LAYOUT:
        raise KeyError(f"no data folder {name!r} (one of {', '.join(LAYOUT)})")
    packaged = resources.files("viewer").joinpath("_data", name)
    if isinstance(packaged, Path) and packaged.is_dir():
        return packaged
    return CHECKOUT / LAYOUT[name]


SHADERS = data_folder("shaders")
"""One .glsl file per program, and the shared includes (viewer.gpu.programs)."""
MODELS = data_folder("models")
"""The shipped networks: NAME.onnx with its card NAME.json (viewer.neural.field)."""
SCENES = data_folder("scenes")
"""The built-in scenes: NAME.obj with NAME.mtl and an optional sidecar NAME.json (viewer.scene)."""
DEFAULT_MODEL = MODELS / "probenet.onnx"
"""The network the neural GI source runs unless told otherwise."""
