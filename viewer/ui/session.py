"""What is being viewed: the loaded scene, the user's edits to it, the shown (edited) scene on the GPU,
its indirect light, voxels for the voxel view, and replacing the scene with a dropped file.

Everything slow (parsing a file, voxelizing, solving) happens off the render thread; `update`, called
once a frame on the render thread, moves finished results onto the GPU.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from viewer.cli_parsing import camera_flags
from viewer.gpu.renderer import Renderer
from viewer.scene import SUPPORTED_SUFFIXES, Scene, load
from viewer.scene.camera import home_camera
from viewer.ui.background import BackgroundTask
from viewer.ui.camera_controller import OrbitCamera
from viewer.ui.gi_sources import GIController
from viewer.ui.messages import PANEL_WIDTH, Message
from viewer.ui.scene_edits import SceneEdits


VIEW_ASPECT = (1280 - PANEL_WIDTH) / 720
"""The 3D view's shape in the window as it opens (1280 x 720, the panel on the right)."""


EDIT_WAIT = 0.5
"""The longest a frame after an edit waits for the GI source's work in flight (`Session.update`)."""


class Session:
    def __init__(self, renderer: Renderer, gi: GIController, scene: Scene, source: str | Path,
                 log=print, edit_interval: float = 0.1, on_gi_ready=None):
        self.renderer = renderer
        self.gi = gi
        self.log = log
        self.on_gi_ready = on_gi_ready
        """Called (no arguments) when the indirect light has settled after a change."""
        self.edit_interval = edit_interval
        """Least seconds between two uploads of an edited scene while a slider is dragged."""
        self.messages: list[Message] = []
        self.loading: BackgroundTask | None = None
        self._loading_path: Path | None = None
        self.scene_version = 0
        self.probes_version = 0
        self._voxels: BackgroundTask | None = None
        self._voxels_wanted = None   # (scene version, voxels per axis) being voxelized
        self._voxels_key = None      # ... and of the voxels the renderer has
        self._gi_was_busy = False
        self.waited = 0.0
        """Seconds the last `update` spent applying edits and waiting for the GI (`frame_seconds`)."""
        self._domain_message: Message | None = None   # the neural source's warning shown now
        self.loads = 0       # scenes loaded since start (for tests)
        self.load_errors = 0
        self.view_aspect = VIEW_ASPECT
        """The 3D view's width over its height, which a scene without a camera of its own is framed for."""
        self._open(scene, source)

    # ---- the scene ------------------------------------------------------------------------------------
    def _open(self, scene: Scene, source: str | Path) -> None:
        self.source = str(source)
        self.edits = SceneEdits(scene)
        self._applied_version = self.edits.version
        self._applied_at = 0.0
        self.scene = scene
        self.scene_version += 1
        self.renderer.set_scene(scene)
        if not self.renderer.lightmapped:
            self.messages.append(Message(f"{len(scene.faces)} triangles: the light is drawn per fragment, without "
                                         f"lightmaps and their final gather (faster and as close on dense meshes).",
                                         warning=True))
        if scene.textured:   # the surface shader's textured variants, compiled now, not in the first frames
            self.renderer.warm_up()
        self.renderer.set_voxels(None)
        self._voxels_key = None
        lo, hi = scene.bounds
        self.camera = OrbitCamera(home_camera(scene, source, self.view_aspect), float(np.linalg.norm(hi - lo)))
        self.gi.set_scene(scene, self.scene_version, new_scene=True)

    @property
    def name(self) -> str:
        return self.edits.base.name

    @property
    def scene_size(self) -> float:
        return self.camera.scene_size

    def load_file(self, path: str | Path) -> None:
        """Start loading a file in the background; the current scene stays until it has loaded."""
        path = Path(path)
        if path.suffix.lower() not in SUPPORTED_SUFFIXES:
            self._load_failed(path, f"{path.name}: unsupported format {path.suffix or '(none)'!r}; "
                                    f"use one of {', '.join(SUPPORTED_SUFFIXES)}")
            return
        self.log(f"loading {path}")
        self.loading, self._loading_path = BackgroundTask(path.name, load, path), path

    def _load_failed(self, path: Path, error: str) -> None:
        self.load_errors += 1
        self.log(f"cannot load {path}: {error}; keeping {self.name}")
        self.messages.append(Message(f"Cannot open {path.name}: {error}", error=True))

    @property
    def busy(self) -> bool:
        """Something the picture waits for is under way (a file, the GI, voxels for the voxel view)."""
        return (self.loading is not None or self.gi.busy or self._voxels is not None
                or self.edits.version != self._applied_version)

    def content_key(self) -> tuple:
        """Changes whenever what the renderer draws changes (scene, probes, voxels)."""
        return (self.scene_version, self.probes_version, self._voxels_key)

    # ---- per frame --------------------------------------------------------------------------------------
    def update(self, view: str, view_rect: tuple[int, int, int, int] | None = None, frame_seconds: float = 0.0) -> None:
        """One frame's work: a finished load opened, edits applied, new probes installed. `view_rect`
        (x, y, width, height) is where the 3D view is drawn: a scene opened later is framed for it.
        `frame_seconds`, what the last drawn frame took: after an edit of colours or lights (the same
        triangles), the GI source's work in flight gets up to that long (at most EDIT_WAIT) to finish, so
        that the frame shows it rather than the old light: on llvmpipe a million-triangle room's frame
        takes 0.2-0.4 s of the same cores a relight needs, and a frame drawn with the old light delayed
        the new one by a whole frame. A drag is not waited for: its traces can take longer than a frame,
        and a dragged lamp's frames would then come half as often."""
        if view_rect is not None and view_rect[3] > 0:
            self.view_aspect = view_rect[2] / view_rect[3]
        self._finish_loading()
        clock, before = time.perf_counter(), self.scene
        if self._apply_edits() and frame_seconds > 0 and self.scene.vertices is before.vertices:
            self.gi.wait(min(frame_seconds, EDIT_WAIT))   # a colour edit's relight; not a drag's traces
        self.waited = time.perf_counter() - clock   # the edits and the wait: not the frame's own cost
        changed, grid = self.gi.update()
        if changed:
            self.renderer.set_probes(grid)
            self.probes_version += 1
        self.renderer.probes_pending = self.gi.busy
        busy = self.gi.busy
        if self._gi_was_busy and not busy:
            line, _, error = self.gi.status()
            self.log(f"GI failed: {error}" if error else f"GI ready: {line}")
            if self.on_gi_ready is not None:
                self.on_gi_ready()
        self._gi_was_busy = busy
        self._show_domain_warning()
        if view == "voxels":
            self._update_voxels()

    def copy_view(self) -> str:
        """The view as capture's flags (`--camera ... --fov ...`): on stderr, on the clipboard and said in the
        window (the C key)."""
        from imgui_bundle import imgui

        camera = self.camera.camera()
        line = camera_flags(camera.origin, camera.target, camera.fov)
        imgui.set_clipboard_text(line)
        self.messages.append(Message(f"The view, copied (capture takes it): {line}"))
        self.log(f"view: {line}")
        return line

    def _show_domain_warning(self) -> None:
        """A message while the neural source shows a scene outside its training domain (replaced when
        the reasons change, withdrawn when there are none)."""
        text = self.gi.domain_warning
        shown = self._domain_message
        if (shown.text if shown else None) == text:
            return
        if shown in self.messages:
            self.messages.remove(shown)
        self._domain_message = Message(text, warning=True) if text else None
        if text:
            self.messages.append(self._domain_message)
            self.log(text)

    def _finish_loading(self) -> None:
        task = self.loading
        if task is None or not task.done:
            return
        self.loading = None
        if task.error is not None:
            self._load_failed(self._loading_path, task.error)
            return
        scene = task.result
        self._open(scene, self._loading_path)
        self.loads += 1
        self.log(f"loaded {self._loading_path} as {scene.name!r}: {len(scene.faces)} triangles, "
                 f"{len(scene.groups)} groups, {task.elapsed:.2f} s")
        self.messages.append(Message(f"Opened {self._loading_path.name} ({len(scene.faces)} triangles)."))

    def _apply_edits(self) -> bool:
        """Apply the edits made since the last time (at most every `edit_interval`); whether it did."""
        now = time.perf_counter()
        if self.edits.version == self._applied_version or now - self._applied_at < self.edit_interval:
            return False
        self.scene = self.edits.apply()
        self._applied_version, self._applied_at = self.edits.version, now
        self.scene_version += 1
        self.gi.set_scene(self.scene, self.scene_version)
        self.gi.start()   # its worker's relight beside the renderer's part
        self.renderer.set_scene(self.scene)
        return True

    def _update_voxels(self) -> None:
        """Voxelize the shown scene for the `voxels` view (in the background, at the GI resolution)."""
        from viewer.rays.voxels import voxelize

        key = (self.scene_version, self.gi.settings.voxels)
        if self._voxels is not None and self._voxels.done:
            task, self._voxels = self._voxels, None
            if task.error is None:
                self.renderer.set_voxels(task.result)
                self._voxels_key = self._voxels_wanted
        if self._voxels is None and self._voxels_key != key:
            self._voxels_wanted = key
            self._voxels = BackgroundTask("voxelize", voxelize, self.scene, key[1])

    def close(self) -> None:
        self.gi.close()
