"""What one headless picture is (CaptureRequest), and the error for a bad one (CaptureError).

viewer.capture.render renders a request; the command line (`python -m viewer capture`, the
viewer without a window: viewer.capture) builds one from its flags. This module imports no GL, so a
command can build a request without paying for it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from viewer.gpu.render_settings import RenderSettings
from viewer.physical.gi import GISettings
from viewer.scene import Camera, DirectionalLight

MAX_SIZE = 8192


class CaptureError(ValueError):
    """Bad capture input (size, camera, view, GI mode, output path): one line, exit status 2."""


@dataclass(frozen=True)
class CaptureRequest:
    """One picture of a scene, rendered headless (viewer.capture.render)."""

    out: str
    """The file written: .png or .jpg, or .npy for the linear HDR radiance (H, W, 3) float32."""
    scene: str = "cornell"
    """A built-in scene name or a scene file."""
    size: tuple[int, int] = (512, 512)
    """(width, height) in pixels, 1..8192 each."""
    gi: str = "off"
    """Where the indirect light comes from: a source of viewer.sources that `capture --gi` offers (`off`:
    direct light only)."""
    view: str = "final"
    """What the picture shows: one of the renderer's views (viewer.gpu.render_settings.VIEWS)."""
    camera: Camera | tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    """A Camera, or the (origin, target) of one with `fov`; None: the view the viewer opens the scene with."""
    fov: float | None = None
    """Vertical field of view in degrees (0..180); None: the camera's own."""
    render: RenderSettings = field(default_factory=RenderSettings)
    """How the frame is drawn (exposure, tone curve, light samples, voxel colour ...)."""
    msaa: int = 4
    """Multisample count (edge anti-aliasing)."""
    supersample: int = 1
    """n > 1: n x n subpixel images averaged in linear light in place of multisampling (a path tracer's
    box filter: a bright lamp's edge as Mitsuba draws it; `OffscreenRenderer.render_hdr`)."""
    sun: DirectionalLight | None = None
    """A directional light in place of the scene's own (None: the scene's, if any)."""
    gi_settings: GISettings = GISettings()
    """The solvers' settings (`--gi solver` and `compute`); its voxels are also the `voxels` view's."""
    model: str | None = None
    """The neural source's .onnx file (None: the shipped model)."""
    turntable: int = 0
    """Frames of a turn around the scene's centre, written as an animated .gif (0: one picture)."""
