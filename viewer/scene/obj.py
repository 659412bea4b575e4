"""Wavefront OBJ + MTL reader (positions, faces, groups and Lambertian materials), and the writer of a
Scene as OBJ + MTL + sidecar.

Our own, because trimesh 5.2 resolves relative (negative) face indices against the end of the whole file
instead of the vertices read so far, which scrambles files like the public-domain CornellBox-Original.obj.
Polygons are fan-triangulated in their vertex order, so the counter-clockwise front is kept; a polygon
whose reverse is in the file too (a two-sided sheet, each side its own material) is fanned from the
corner both share first (`_sheet_fans`), so that each of its triangles has its reversed twin.
"""

from __future__ import annotations

import io
import json
import re
from pathlib import Path

import numpy as np

from viewer.scene.files import check_readable, companion
from viewer.scene.types import Scene, SceneError

DEFAULT_ALBEDO = (0.7, 0.7, 0.7)


def read_mtl(path: Path) -> dict[str, dict[str, np.ndarray]]:
    """name -> {"Kd": rgb, "Ke": rgb} for every material in an MTL file."""
    materials: dict[str, dict[str, np.ndarray]] = {}
    current = None
    for number, _, words in _statements(_lines(path)):
        key = words[0]
        if key == "newmtl":
            current = " ".join(words[1:]) or "default"
            materials[current] = {}
        elif key in ("Kd", "Ke") and current is not None:
            materials[current][key] = _rgb(words[1:], path, number)
    return materials


def read(path: Path) -> Scene:
    """The scene of an OBJ file (and its MTL). A file of plain triangles (`v x y z` and `f i j k` lines
    with absolute indices: what scanners and our own writer write) has its numbers parsed by numpy's
    reader, the lines sorted by their first two characters (`_read_plain`: 45 ms for a 68k-triangle
    scan, where reading it in bulk below took 135 ms on 2 cores); other files are read in bulk, the
    numbers converted all at once; a file the bulk reading does not take as it is (a bad number or
    index, a face of fewer than three corners) is read a line at a time, which says where it is wrong.
    All three give the same scene."""
    lines = _lines(path)
    return _read_plain(path, lines) or _read_bulk(path, lines) or _read_lines(path, lines)


class _Materials:
    """The `usemtl` and `mtllib` lines as both readers take them: the material names in order of first
    use, the current one, and the libraries' materials."""

    def __init__(self):
        self.names: list[str] = []
        self.current = _material_index(self.names, "default")
        self.materials: dict[str, dict[str, np.ndarray]] = {}

    def line(self, key: str, words: list[str], raw: str, path: Path) -> None:
        if key == "usemtl":
            self.current = _material_index(self.names, " ".join(words[1:]) or "default")
        elif key == "mtllib":   # one name with spaces, or several names; only inside the scene's folder
            rest = raw.split("#", 1)[0].strip()[len("mtllib"):].strip()
            libraries = [rest] if _is_file(path.parent / rest) else rest.split()
            for library in filter(None, (companion(path, name) for name in libraries)):
                if _is_file(library):
                    check_readable(library, "material library")
                    self.materials.update(read_mtl(library))

    def scene(self, path: Path, positions, faces, face_material, polygons=()) -> Scene:
        if not len(faces):
            raise SceneError(f"{path}: no faces found")
        if len(polygons):
            faces = _sheet_fans(np.asarray(positions, np.float64).reshape(-1, 3), faces, polygons)
        materials, names = self.materials, self.names
        albedo = np.array([materials.get(n, {}).get("Kd", DEFAULT_ALBEDO) for n in names], np.float64)
        emission = np.array([materials.get(n, {}).get("Ke", (0.0, 0.0, 0.0)) for n in names], np.float64)
        used, group = np.unique(np.asarray(face_material), return_inverse=True)
        return Scene(path.stem, np.asarray(positions, np.float64).reshape(-1, 3), np.asarray(faces, np.int64),
                     albedo[used][group], emission[used][group], group, tuple(names[i] for i in used))


def _read_plain(path: Path, lines: list[str]) -> Scene | None:
    """The scene of a file whose vertices are `v x y z` lines and whose faces are `f i j k` triangles
    of absolute indices, or None for any other (polygons, `i/t/n` corners, relative indices, a line that
    starts with a space: `_read_bulk` reads those)."""
    vertices: list[str] = []
    triangles: list[str] = []
    state = _Materials()
    switches: list[tuple[int, int]] = [(0, state.current)]   # (triangles before it, material) at each line
    for raw in lines:
        head = raw[:2]
        if head == "v ":
            vertices.append(raw)
        elif head == "f ":
            triangles.append(raw)
        elif head not in ("vn", "vt", "# ", "") and raw[:1] != "#":
            words = raw.split("#", 1)[0].split()
            if not words:
                continue
            if words[0] in ("v", "f"):
                return None
            state.line(words[0], words, raw, path)
            switches.append((len(triangles), state.current))
    if not vertices or not triangles:
        return None
    text = "\n".join(triangles)
    if "#" in text:   # comments after some faces
        text = re.sub(r"#[^\n]*", "", text)
    if "/" in text or _words(text) != 4 * len(triangles):   # corners with slashes, polygons
        return None
    try:
        positions = np.loadtxt(vertices, np.float64, comments="#", usecols=(1, 2, 3), ndmin=2)
        corners = np.loadtxt(triangles, np.int64, comments="#", usecols=(1, 2, 3), ndmin=2)
    except ValueError:   # too few numbers on a line, or one that is not a number
        return None
    if not np.all(np.isfinite(positions)) or corners.min() < 1 or corners.max() > len(positions):
        return None
    starts, current = np.array(switches, np.int64).T   # each material from its line to the next one's
    material = np.repeat(current, np.diff(np.append(starts, len(triangles))))
    return state.scene(path, positions, corners - 1, material)


def _words(text: str) -> int:
    """How many words (runs of other characters between spaces, tabs and line ends) `text` has: counted by
    numpy, where str.split would make every word a string."""
    data = np.frombuffer(text.encode("utf-8", "replace"), np.uint8)
    gap = np.ones(len(data) + 1, bool)
    gap[1:] = (data == 32) | (data == 9) | (data == 10) | (data == 13)
    return int(np.count_nonzero(gap[:-1] & ~gap[1:]))


def _read_bulk(path: Path, lines: list[str]) -> Scene | None:
    """The scene, with every coordinate and index kept as text until the end, or None where the file
    needs `_read_lines`' checks."""
    coordinates: list[str] = []
    corners: list[str] = []          # three a triangle, polygons fanned from their first corner
    so_far: list[int] = []           # vertices read before each triangle's line (relative indices)
    face_material: list[int] = []
    polygons: list[int] = []         # (first triangle, corners) of each polygon of four corners or more
    state = _Materials()
    for _, raw, words in _statements(lines):
        key = words[0]
        if key == "v":
            if len(words) < 4:
                return None
            coordinates.extend(words[1:4])
        elif key == "f":
            count = len(words) - 1
            if count < 3:
                return None
            if count == 3:
                corners.extend(words[1:])
            else:
                polygons.extend((len(corners) // 3, count))
                for k in range(2, count):
                    corners.extend((words[1], words[k], words[k + 1]))
            so_far.extend([len(coordinates) // 3] * (count - 2))
            face_material.extend([state.current] * (count - 2))
        else:
            state.line(key, words, raw, path)
    try:
        positions = np.array(coordinates, np.float64).reshape(-1, 3)
        try:
            index = np.array(corners, np.int64)
        except ValueError:   # v/vt/vn corners: the position's index is the first
            index = np.array([c.split("/", 1)[0] for c in corners], np.int64)
    except ValueError:
        return None
    vertices = np.repeat(np.asarray(so_far, np.int64), 3)
    resolved = np.where(index > 0, index - 1, vertices + index)
    if not np.all(np.isfinite(positions)) or np.any((index == 0) | (resolved < 0) | (resolved >= vertices)):
        return None
    return state.scene(path, positions, resolved.reshape(-1, 3), face_material, polygons)


def _read_lines(path: Path, lines: list[str]) -> Scene:
    """The scene a line at a time, each number checked where it is read."""
    positions: list[list[float]] = []
    faces: list[tuple[int, int, int]] = []
    face_material: list[int] = []
    polygons: list[int] = []
    state = _Materials()
    for number, raw, words in _statements(lines):
        key = words[0]
        if key == "v":
            if len(words) < 4:
                raise SceneError(f"{path}:{number}: vertex needs three coordinates")
            positions.append(_floats(words[1:4], path, number))
        elif key == "f":
            corners = [_index(w, len(positions), path, number) for w in words[1:]]
            if len(corners) < 3:
                raise SceneError(f"{path}:{number}: a face needs at least three vertices")
            if len(corners) > 3:
                polygons.extend((len(faces), len(corners)))
            for k in range(1, len(corners) - 1):
                faces.append((corners[0], corners[k], corners[k + 1]))
                face_material.append(state.current)
        else:
            state.line(key, words, raw, path)
    return state.scene(path, positions, faces, face_material, polygons)


WEIGHTS = np.sqrt([2.0, 3.0, 5.0])
"""A corner's weight: its position's dot product with these irrational numbers (distinct corners, distinct
weights)."""


def _sheet_fans(positions: np.ndarray, faces, polygons: list[int]) -> np.ndarray:
    """`faces` (T, 3) with every polygon that has a reversed twin in the file fanned again from its corner
    of least weight. `polygons` lists (first triangle, corners) of each polygon fanned from its first
    corner. A sheet written as `f 1 2 3 4` and `f 4 3 2 1` splits along two different diagonals when each
    is fanned from its own first corner, and no triangle of one side then has the same corners as one of
    the other: each ray or pixel would meet whichever face came first. Fanned from the same corner, the
    two sides split alike. Polygons without a reversed twin keep their triangles."""
    faces = np.array(faces, np.int64).reshape(-1, 3)
    table = np.asarray(polygons, np.int64).reshape(-1, 2)
    weight = positions @ WEIGHTS
    for n in np.unique(table[:, 1]):
        rows = table[table[:, 1] == n, 0][:, None] + np.arange(n - 2)
        fan = faces[rows]   # (P, n - 2, 3): (c0, ck, ck+1)
        corners = np.concatenate([fan[:, 0, :2], fan[:, :, 2]], axis=1)
        ranked = np.sort(weight[corners], axis=1)
        key = ranked @ np.sqrt(np.arange(7, 7 + n, dtype=np.float64))   # any order of the same corners alike
        order = np.argsort(key, kind="stable")
        equal = np.flatnonzero(key[order[1:]] == key[order[:-1]])
        if not len(equal):   # no two polygons on the same corners: the usual file, one sort
            continue
        sheet = np.zeros(len(corners), bool)
        step = np.diff(equal) != 1
        pair = np.r_[True, step] & np.r_[step, True]   # two polygons of the same corners (a sheet's sides)
        two = np.stack([order[equal[pair]], order[equal[pair] + 1]], axis=1)
        front = _fronts(positions[corners[two]])
        facing = np.all(ranked[two[:, 0]] == ranked[two[:, 1]], axis=1) & (np.sum(front[:, 0] * front[:, 1], 1) < 0)
        sheet[two[facing].ravel()] = True
        for first, last in _runs(equal[~pair]):   # more of the same corners: do some face each other?
            members = order[first:last + 2]
            members = members[np.all(ranked[members] == ranked[members[0]], axis=1)]
            front = _fronts(positions[corners[members]])
            sheet[members[(front @ front.T < 0).any(axis=1)]] = True
        if not sheet.any():
            continue
        turned = corners[sheet]
        start = np.argmin(weight[turned], axis=1)[:, None]
        turned = np.take_along_axis(turned, (start + np.arange(n)) % n, axis=1)
        k = np.arange(1, n - 1)
        faces[rows[sheet]] = np.stack([np.repeat(turned[:, :1], n - 2, axis=1), turned[:, k], turned[:, k + 1]],
                                      axis=2)
    return faces


def _fronts(corners: np.ndarray) -> np.ndarray:
    """(..., 3) the fronts of polygons of `corners` (..., n, 3), by Newell's sum (unnormalized)."""
    return np.cross(corners, np.roll(corners, -1, axis=-2)).sum(axis=-2)


def _runs(index: np.ndarray):
    """(first, last) of each run of consecutive integers in sorted `index`."""
    if not len(index):
        return []
    breaks = np.flatnonzero(np.diff(index) != 1)
    return zip(index[np.r_[0, breaks + 1]].tolist(), index[np.r_[breaks, len(index) - 1]].tolist())


def _statements(lines: list[str]):
    """(line number, line, its words before any comment) of each line that has words."""
    for number, raw in enumerate(lines, 1):
        words = raw.split("#", 1)[0].split()
        if words:
            yield number, raw, words


def _lines(path: Path):
    try:
        text = path.read_bytes().decode("utf-8", errors="replace")
    except OSError as exc:
        raise SceneError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if "\x00" in text:
        raise SceneError(f"{path}: not a text file (binary data in an OBJ/MTL)")
    return text.splitlines()


def _is_file(path: Path) -> bool:
    """A material library that cannot even be looked up (a name too long for the file system, say) is
    skipped like a missing one, not an error: the geometry is still good."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


def _material_index(names: list[str], name: str) -> int:
    if name not in names:
        names.append(name)
    return names.index(name)


def _floats(words, path, number, what: str = "coordinate") -> list[float]:
    """The numbers of an OBJ or MTL line; `what` they are (a coordinate, a colour) names a bad one."""
    try:
        values = [float(w) for w in words]
    except ValueError:
        raise SceneError(f"{path}:{number}: {' '.join(words)!r} is not a number") from None
    if not all(np.isfinite(values)):
        raise SceneError(f"{path}:{number}: NaN or infinite {what}")
    return values


def _rgb(words, path, number) -> np.ndarray:
    values = _floats(words[:3], path, number, "colour")
    if len(values) == 1:
        values = values * 3
    if len(values) != 3:
        raise SceneError(f"{path}:{number}: a colour needs three numbers")
    return np.asarray(values, np.float64)


def _index(word: str, count: int, path, number) -> int:
    """OBJ position index (1-based, negative = relative to the vertices read so far) -> 0-based."""
    try:
        i = int(word.split("/", 1)[0])
    except ValueError:
        raise SceneError(f"{path}:{number}: face index {word!r} is not an integer") from None
    resolved = i - 1 if i > 0 else count + i
    if i == 0 or not 0 <= resolved < count:
        raise SceneError(f"{path}:{number}: face index {i} out of range (1..{count} vertices so far)")
    return resolved


def write(scene: Scene, path: Path) -> None:
    """OBJ + MTL + sidecar JSON (camera, sun) that `viewer.scene.load` reads back to the same scene, each
    coordinate to the last bit (one material per group: the albedo and emission of the group's first
    face)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    obj, mtl = io.StringIO(), []
    obj.write(f"mtllib {path.stem}.mtl\n")
    first = 1  # OBJ indices count from 1 over the whole file
    for g, group in enumerate(scene.groups):
        faces = scene.faces[scene.face_group == g]
        if not len(faces):
            continue
        used, local = np.unique(faces, return_inverse=True)
        obj.write(f"g {group}\nusemtl {group}\n")
        np.savetxt(obj, scene.vertices[used], fmt="v %.17g %.17g %.17g")
        np.savetxt(obj, local.reshape(-1, 3) + first, fmt="f %d %d %d")
        first += len(used)
        albedo, emission = scene.albedo[scene.face_group == g][0], scene.emission[scene.face_group == g][0]
        mtl.append(f"newmtl {group}\nKd {' '.join(map(repr, albedo.tolist()))}\n"
                   f"Ke {' '.join(map(repr, emission.tolist()))}\n")
    path.write_text(obj.getvalue())
    path.with_suffix(".mtl").write_text("".join(mtl))
    c = scene.camera
    side = {"camera": {"origin": list(c.origin), "target": list(c.target), "up": list(c.up), "fov": c.fov}}
    if scene.sun is not None:
        side["sun"] = {"direction": scene.sun.direction.tolist(), "irradiance": scene.sun.irradiance.tolist()}
    path.with_suffix(".json").write_text(json.dumps(side, indent=2) + "\n")
