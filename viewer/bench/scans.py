"""Scanned-mesh rooms for the benchmark: a public scan standing in the Cornell box, refined to a triangle
count, so that the cost of real meshes is measured on scenes anyone can make again.

    cp bun_zipper.ply bunny.ply
    python -m viewer.bench.scans --mesh bunny.ply --triangles 68000 272000 1000000 --out scans/

writes scans/bunny-room-68k.obj, -272k and -1m (each with its .mtl and camera sidecar; the rooms are named
after the mesh file, up to its first underscore: bun_zipper.ply itself gives bun-room-68k.obj), which every
command opens (`python -m viewer capture scans/bunny-room-272k.obj --out x.png`). The scan is any mesh
trimesh reads; the one the docs measure is the Stanford bunny (the Stanford 3D Scanning Repository,
https://graphics.stanford.edu/data/3Dscanrep/: `bunny/reconstruction/bun_zipper.ply`, 69,451
triangles), which is not shipped here: the repository asks that its scans be taken from it.

The scan is centred (its vertices' mean), scaled to 0.9 tall (the box is 2), set on the box's floor in its free front-
left quarter, and its triangles are split until the room has the count asked for. Each pass splits the
largest triangles along their longest edge, at its midpoint: the surface stays the same, point for
point, and the triangles stay of like size, as a finer scan's would. A count below the scan's own keeps
the scan as it is.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from viewer.scene import load
from viewer.scene.obj import write
from viewer.scene.types import Scene

ROOM = "cornell"
"""The room the scan stands in (the Cornell box: two blocks, one ceiling lamp)."""
PLACE = (-0.35, 0.35)
"""Where the scan stands on the floor: (x, z) of its centre, in the box's front-left quarter, clear of
both blocks."""


def refine(vertices: np.ndarray, faces: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The same surface in `count` triangles (or the input where it has as many already): passes that
    each split up to all of the largest triangles along their longest edge."""
    vertices, faces = np.asarray(vertices, np.float64), np.asarray(faces, np.int64)
    while len(faces) < count:
        corners = vertices[faces]
        edges = np.linalg.norm(corners[:, [1, 2, 0]] - corners, axis=2)   # edge e runs corner e -> e + 1
        longest = np.argmax(edges, axis=1)
        split = np.argsort(-edges.max(axis=1), kind="stable")[:count - len(faces)]
        e = longest[split]
        rows = np.arange(len(split))
        a = faces[split, e]
        b = faces[split, (e + 1) % 3]
        c = faces[split, (e + 2) % 3]
        middle = len(vertices) + rows
        vertices = np.vstack([vertices, 0.5 * (vertices[a] + vertices[b])])
        kept = np.delete(faces, split, axis=0)
        faces = np.vstack([kept, np.column_stack([a, middle, c]), np.column_stack([middle, b, c])])
    return vertices, faces


def scan_room(scan: Scene, triangles: int, height: float = 0.9, albedo: float = 0.7) -> Scene:
    """The Cornell box with `scan` standing on its floor, `height` tall (the box is 2 high) and grey
    (`albedo`), `triangles` in all (or the box and the scan as they are, if that is more)."""
    room = load(ROOM)
    lo, hi = scan.bounds
    up = room.face_normals[:, 1] > 0.99
    floor = float(room.triangles[up][..., 1].min())                      # the top of the floor: the lowest face up
    vertices = (scan.vertices - scan.vertices.mean(axis=0)) * (height / float((hi - lo)[1]))
    vertices[:, 1] += floor - vertices[:, 1].min()                        # standing on it
    vertices[:, [0, 2]] += PLACE
    vertices, faces = refine(vertices, scan.faces, triangles - len(room.faces))
    n = len(room.vertices)
    group = len(room.groups)
    return Scene(f"{scan.name}-room", np.vstack([room.vertices, vertices]), np.vstack([room.faces, faces + n]),
                 np.vstack([room.albedo, np.full((len(faces), 3), albedo)]),
                 np.vstack([room.emission, np.zeros((len(faces), 3))]),
                 np.concatenate([room.face_group, np.full(len(faces), group)]), (*room.groups, scan.name),
                 camera=room.camera)


def label(triangles: int) -> str:
    """68000 -> '68k', 1000000 -> '1m'."""
    if triangles >= 1_000_000 and triangles % 1_000_000 == 0:
        return f"{triangles // 1_000_000}m"
    return f"{triangles // 1000}k" if triangles >= 1000 else str(triangles)


def main(argv=None) -> int:
    from viewer.cli_parsing import tool_parser

    parser = tool_parser(prog="python -m viewer.bench.scans",
                         description="Write the Cornell box with a scanned mesh standing in it, refined to "
                                     "each triangle count, as OBJ scenes (the benchmark's scanned-mesh rooms).")
    parser.add_argument("--mesh", type=Path, required=True,
                        help="the scan: any mesh file trimesh reads (the docs use the Stanford bunny's "
                             "bun_zipper.ply)")
    parser.add_argument("--triangles", type=int, nargs="+", default=[68000, 272000, 1000000],
                        help="triangle counts of the rooms (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=Path("scans"), help="folder (default: %(default)s)")
    args = parser.parse_args(argv)
    scan = load(args.mesh)
    name = args.mesh.stem.split("_")[0]
    for triangles in args.triangles:
        room = scan_room(replace(scan, name=name), triangles)
        path = args.out / f"{name}-room-{label(triangles)}.obj"
        write(room, path)
        print(f"{path}: {len(room.faces)} triangles")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
