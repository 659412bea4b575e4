"""Camera matrices for the renderer (pyrr), in the math convention clip = M @ [p, 1].

pyrr builds matrices for row vectors (p @ M); they are transposed here once, so that every matrix in
`viewer.gpu` reads like the textbook. `gl_bytes` writes a matrix in the column-major layout a GLSL
`mat4` uniform expects.
"""

from __future__ import annotations

import numpy as np
import pyrr

from viewer.scene import Camera


def view_matrix(camera: Camera) -> np.ndarray:
    """World -> eye space (the camera looks down -z, y up)."""
    eye, target, up = (np.asarray(v, np.float64) for v in (camera.origin, camera.target, camera.up))
    return np.asarray(pyrr.matrix44.create_look_at(eye, target, up), np.float64).T


def perspective(fov_y: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL perspective projection; `fov_y` is the vertical field of view in degrees."""
    return np.asarray(pyrr.matrix44.create_perspective_projection(fov_y, aspect, near, far), np.float64).T


def orthographic(half_width: float, half_height: float, near: float, far: float) -> np.ndarray:
    return np.asarray(pyrr.matrix44.create_orthogonal_projection(
        -half_width, half_width, -half_height, half_height, near, far), np.float64).T


def look_along(eye, forward, up) -> np.ndarray:
    """A view matrix from a position and a viewing direction."""
    eye = np.asarray(eye, np.float64)
    return view_matrix(Camera(tuple(eye), tuple(eye + np.asarray(forward, np.float64)), tuple(up)))


def clip_range(camera: Camera, lo: np.ndarray, hi: np.ndarray) -> tuple[float, float]:
    """Near and far planes that hold the box [lo, hi] seen from the camera (inside it too)."""
    centre = 0.5 * (np.asarray(lo) + np.asarray(hi))
    radius = max(0.5 * float(np.linalg.norm(np.asarray(hi) - np.asarray(lo))), 1e-6)
    distance = float(np.linalg.norm(np.asarray(camera.origin) - centre))
    far = distance + 1.5 * radius
    near = max(distance - 1.5 * radius, 1e-3 * radius)
    return near, far


def view_projection(camera: Camera, aspect: float, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Perspective projection @ view for a scene in the box [lo, hi]."""
    near, far = clip_range(camera, lo, hi)
    return perspective(camera.fov, aspect, near, far) @ view_matrix(camera)


def jittered(view_proj: np.ndarray, jitter: tuple[float, float], size: tuple[int, int]) -> np.ndarray:
    """`view_proj` with the image moved by `jitter` pixels (x right, y up) in an image of `size`: a
    translation in clip space, 2 / size per pixel (supersampling's subpixel offsets)."""
    if jitter == (0.0, 0.0):
        return view_proj
    shift = np.eye(4)
    shift[0, 3], shift[1, 3] = 2.0 * jitter[0] / size[0], 2.0 * jitter[1] / size[1]
    return shift @ view_proj


def gl_bytes(matrix: np.ndarray) -> bytes:
    """A 4x4 math-convention matrix as the bytes of a GLSL mat4 (column-major float32)."""
    return np.ascontiguousarray(np.asarray(matrix, np.float32).T).tobytes()


def look_at(origin, target, fov: float | None = None, up=(0.0, 1.0, 0.0)) -> Camera:
    """A camera at `origin` looking at `target` (`--camera ox,oy,oz,tx,ty,tz`, parsed by
    viewer.cli_parsing.parse_camera), with `up` unless it looks straight up or down."""
    origin, target = np.asarray(origin, np.float64), np.asarray(target, np.float64)
    if np.linalg.norm(target - origin) < 1e-9:
        raise ValueError("the camera's origin and target are the same point")
    forward = (target - origin) / np.linalg.norm(target - origin)
    if abs(float(forward @ np.asarray(up))) > 0.999:  # looking straight up or down: pick another up
        up = (0.0, 0.0, -1.0) if forward[1] < 0 else (0.0, 0.0, 1.0)
    return Camera(tuple(float(v) for v in origin), tuple(float(v) for v in target), tuple(up),
                  float(fov) if fov else Camera.fov)
