"""What the viewer does on its own when the command line asks (viewer.ui.options), for tests, benchmarks
and the soak: save the picture once it has settled (--screenshot), quit after --frames or --quit-after
seconds, time --bench N redraws, log memory and live GL objects after every load (--resources), and
write the window's state as JSON (--stats). The window asks it after every frame; it draws nothing.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

from viewer.memory import Usage


class UnattendedRun:
    """The flags' state over the run. With --resources the window watches its context for GL objects
    from the start (viewer.gpu.gl_objects.watch), before this exists."""

    def __init__(self, options, ctx, session, viewport, times, view, log):
        self.options, self.ctx, self.log = options, ctx, log
        self.session, self.viewport, self.times, self.view = session, viewport, times, view
        self.started = time.perf_counter()
        self.screenshot_taken = False
        self.bench_from: int | None = None   # frame number the --bench frames started at
        self.resources_key = None   # (loads, load errors) of the last --resources line

    @property
    def settled(self) -> bool:
        """Nothing under way (loading, GI, edits) and the full-resolution picture of it drawn."""
        return self.viewport.settled and not self.session.busy

    def screenshot_due(self, frames: int) -> bool:
        """--screenshot: the settled picture is on the screen and not saved yet."""
        return bool(self.options.screenshot) and not self.screenshot_taken and frames >= 2 and self.settled

    def after_frame(self, frames: int, settled_shot: bool) -> bool:
        """After frame number `frames` (settled_shot: --screenshot was saved in it); True: quit now."""
        o = self.options
        if settled_shot:
            self.screenshot_taken = True
        done = (settled_shot or (o.frames is not None and frames >= o.frames)
                or (o.quit_after is not None and time.perf_counter() - self.started >= o.quit_after))
        done = self._bench(frames) or done
        self._log_resources()
        return done

    def _bench(self, frames: int) -> bool:
        """--bench N: when settled, time N full redraws (the summary printed at exit), then quit."""
        count = self.options.bench
        if not count:
            return False
        if self.bench_from is None:
            if frames >= 2 and self.settled:
                self.bench_from = frames
                self.view.redraw_always = True
                self.times.restart_summary()
                self.log(f"bench: settled after {time.perf_counter() - self.started:.1f} s; timing {count} redraws")
            return False
        return frames - self.bench_from >= count + 3   # + the GPU results still in flight

    def _log_resources(self) -> None:
        """--resources: one line of resident memory and live GL objects once the picture has settled
        after the start, a load or a failed load."""
        key = (self.session.loads, self.session.load_errors)
        if not self.options.resources or key == self.resources_key or not self.settled:
            return
        self.resources_key = key
        usage = Usage.measure(self.ctx, trim=self.options.resources == "held")
        self.log(f"resources: {usage}, loads {key[0]}, load errors {key[1]}")

    def write_stats(self, frames: int, window_size, gl_description: str, shader_error: str | None) -> None:
        """--stats FILE: the state a test or a benchmark wants to see, as JSON (nothing without --stats)."""
        if not self.options.stats:
            return
        redraws, every = self.times.summary(redrawn_only=True), self.times.summary()
        s = self.session
        camera = s.camera.camera()
        stats = {
            "scene": s.name, "source": s.source, "triangles": int(len(s.scene.faces)),
            "groups": list(s.scene.groups), "loads": s.loads, "load_errors": s.load_errors,
            "gi_source": s.gi.source, "gi_status": s.gi.status()[0], "view": self.view.view,
            "gi_settings": dataclasses.asdict(s.gi.settings),
            "camera": {"origin": list(camera.origin), "target": list(camera.target), "fov": camera.fov},
            "frames": frames, "frame_times_redraws": redraws, "frame_times_all": every,
            "window": list(window_size), "gl": gl_description,
            "messages": [{"text": m.text, "error": m.error, "warning": m.warning} for m in s.messages],
            "shader_error": shader_error, "help_shown": self.view.show_help,
        }
        Path(self.options.stats).write_text(json.dumps(stats, indent=2))
