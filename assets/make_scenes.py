"""Regenerate the built-in scenes in `assets/scenes/` (OBJ + MTL + camera sidecar JSON).

    python assets/make_scenes.py

Every number of every scene is in this file; the generated files are never edited by hand. The mesh
primitives and transforms come from `viewer/scene/meshes.py` (shared with the procedural training scenes).

Conventions (docs/ARCHITECTURE.md): y up, Lambertian, MTL `Kd` = albedo, `Ke` = emitted radiance, emitters
one-sided from the counter-clockwise front face. Every object is its own `usemtl` group with its own
material (same name), so each can be recoloured alone. Walls face into the box, closed objects face
outwards, ceiling lights face down.

Sources of the numbers
----------------------
`cornell`: Mitsuba 3's `mitsuba.cornell_box()` (mitsuba/python/util.py, Mitsuba 3.9.1), reproduced
exactly: the box is [-1, 1]^3 with the open side at z = +1; a `rectangle` is [-1, 1]^2 in the xy plane
facing +z, a `cube` is [-1, 1]^3; `to_world` composes like `ScalarTransform4f().translate().rotate()
.scale()`, i.e. T @ R @ S. Reflectances: white (0.885809, 0.698859, 0.666422), red (0.570068, 0.0430135,
0.0443706), green (0.105421, 0.37798, 0.076425); the light's bsdf is the white one and its radiance
(18.387, 13.9873, 6.75357). Camera: origin (0, 0, 3.9) looking at the origin, vertical fov 39.3077 deg.

`paper-train-1` ... `paper-train-5`: the training layouts of R. Yang, "Reconstruction of radiance field
with neural network for real-time rendering": Cornell-box scenes in which the placement of the objects
and the colours of the meshes vary, lit by one or two area emitters. The paper describes the layouts
but does not list their numbers; the numbers below are ours. They keep the `cornell` box, camera and
white; every layout keeps the front-left floor area (x < -0.25, z > 0.25) free, because that is where
the held-out `paper-test` scene puts its new object.

`paper-test`: the held-out scene: the `cornell` layout plus a sphere (radius 0.22) at the front left,
where no training layout has an object, and the back wall pink (0.85, 0.45, 0.55).
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # run as a script from anywhere
from viewer.scene.meshes import (X_AXIS, Y_AXIS, Mesh, cube, cylinder, overlap, rectangle,  # noqa: E402
                           rotate, scale, transformed, translate, uv_sphere)

OUT = Path(__file__).resolve().parent / "scenes"

# ---- Mitsuba's cornell_box() ------------------------------------------------------------------------
WHITE = (0.885809, 0.698859, 0.666422)
RED = (0.570068, 0.0430135, 0.0443706)
GREEN = (0.105421, 0.37798, 0.076425)
CORNELL_RADIANCE = (18.387, 13.9873, 6.75357)
CAMERA = {"origin": [0.0, 0.0, 3.9], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0], "fov": 39.3077}

# ---- our colours for the paper's layouts --------------------------------------------------------------
BLUE = (0.10, 0.15, 0.55)
YELLOW = (0.75, 0.60, 0.10)
ORANGE = (0.80, 0.40, 0.10)
SKY = (0.30, 0.60, 0.80)
GREY_BLUE = (0.55, 0.60, 0.75)
LEMON = (0.85, 0.80, 0.20)
BRICK = (0.70, 0.20, 0.20)
GREY = (0.70, 0.70, 0.70)
PURPLE = (0.50, 0.30, 0.70)
PINK = (0.85, 0.45, 0.55)

WALLS = ("floor", "ceiling", "back", "red-wall", "green-wall")
FLOOR_Y = -1.0
LIGHT_Y = 0.99
"""Height of the ceiling lights, as in `cornell_box()`: just below the ceiling, facing down."""


# ---- scene parts ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Part:
    """One object: its own group and material in the OBJ."""

    name: str
    mesh: Mesh
    albedo: tuple[float, float, float]
    radiance: tuple[float, float, float] = (0.0, 0.0, 0.0)


def walls(red=RED, green=GREEN, back=WHITE, floor=WHITE, ceiling=WHITE) -> list[Part]:
    """The box of `cornell_box()`; `red`/`green` are the colours of the x = -1 / x = +1 walls."""
    return [
        Part("floor", transformed(rectangle(), translate(0, -1, 0) @ rotate(X_AXIS, -90)), floor),
        Part("ceiling", transformed(rectangle(), translate(0, 1, 0) @ rotate(X_AXIS, 90)), ceiling),
        Part("back", transformed(rectangle(), translate(0, 0, -1)), back),
        Part("green-wall", transformed(rectangle(), translate(1, 0, 0) @ rotate(Y_AXIS, -90)), green),
        Part("red-wall", transformed(rectangle(), translate(-1, 0, 0) @ rotate(Y_AXIS, 90)), red),
    ]


def ceiling_light(name: str, x: float, z: float, half_x: float, half_z: float, radiance) -> Part:
    """A rectangle light centred at (x, LIGHT_Y, z), facing down (rotate x 90 maps +z to -y)."""
    to_world = translate(x, LIGHT_Y, z) @ rotate(X_AXIS, 90) @ scale(half_x, half_z, 1.0)
    return Part(name, transformed(rectangle(), to_world), WHITE, tuple(radiance))


def box(name: str, x: float, z: float, half, yaw: float, albedo=WHITE, base: float = FLOOR_Y) -> Part:
    """A box standing on height `base`, turned `yaw` degrees about y; `half` = half extents (x, y, z)."""
    hx, hy, hz = half
    return Part(name, transformed(cube(), translate(x, base + hy, z) @ rotate(Y_AXIS, yaw)
                                  @ scale(hx, hy, hz)), albedo)


def sphere(name: str, x: float, z: float, radius: float, albedo=WHITE, base: float = FLOOR_Y) -> Part:
    return Part(name, transformed(uv_sphere(), translate(x, base + radius, z) @ scale(radius)), albedo)


def column(name: str, x: float, z: float, radius: float, half_height: float, albedo=WHITE) -> Part:
    to_world = translate(x, FLOOR_Y + half_height, z) @ scale(radius, half_height, radius)
    return Part(name, transformed(cylinder(), to_world), albedo)


# ---- the scenes ------------------------------------------------------------------------------------------

def cornell() -> list[Part]:
    """`mitsuba.cornell_box()`, transforms copied verbatim."""
    return walls() + [
        Part("small-box", transformed(cube(), translate(0.335, -0.7, 0.38) @ rotate(Y_AXIS, -17)
                                      @ scale(0.3)), WHITE),
        Part("large-box", transformed(cube(), translate(-0.33, -0.4, -0.28) @ rotate(Y_AXIS, 18.25)
                                      @ scale(0.3, 0.61, 0.3)), WHITE),
        Part("light", transformed(rectangle(), translate(0.0, 0.99, 0.01) @ rotate(X_AXIS, 90)
                                  @ scale(0.23, 0.19, 0.19)), WHITE, CORNELL_RADIANCE),
    ]


def paper_train_1() -> list[Part]:
    """Cornell walls and light; a tall box back right, a sphere front right, a small box back left."""
    return walls() + [
        box("tall-box", 0.40, -0.40, (0.28, 0.55, 0.28), -25),
        sphere("sphere", 0.30, 0.45, 0.30),
        box("small-box", -0.50, -0.50, (0.20, 0.20, 0.20), 10),
        ceiling_light("light", 0.0, 0.01, 0.23, 0.19, CORNELL_RADIANCE),
    ]


def paper_train_2() -> list[Part]:
    """Blue and yellow side walls; a warm light on the left, a cool one on the right; a cylinder at the
    back and an orange box front right."""
    return walls(red=BLUE, green=YELLOW) + [
        column("cylinder", 0.0, -0.45, 0.30, 0.45),
        box("small-box", 0.50, 0.50, (0.18, 0.18, 0.18), 40, ORANGE),
        ceiling_light("light", -0.45, 0.0, 0.15, 0.25, (15.0, 11.0, 6.0)),
        ceiling_light("light-2", 0.45, 0.0, 0.15, 0.25, (8.0, 10.0, 15.0)),
    ]


def paper_train_3() -> list[Part]:
    """Cornell walls with a grey floor; one white light off centre towards the front; a sphere resting on
    a box at the back left, a thin light-blue pillar on the right."""
    return walls(floor=(0.5, 0.5, 0.5)) + [
        box("box", -0.45, -0.30, (0.30, 0.30, 0.30), 30),
        sphere("sphere", -0.45, -0.30, 0.25, base=FLOOR_Y + 0.60),
        box("pillar", 0.55, 0.10, (0.15, 0.70, 0.15), 0, SKY),
        ceiling_light("light", 0.25, 0.35, 0.30, 0.20, (14.0, 14.0, 14.0)),
    ]


def paper_train_4() -> list[Part]:
    """Grey-blue back wall; coloured objects: a large yellow sphere at the back, a red box front right;
    two strip lights, one behind the other."""
    return walls(back=GREY_BLUE) + [
        sphere("sphere", 0.10, -0.45, 0.40, LEMON),
        box("box", 0.55, 0.45, (0.20, 0.35, 0.20), 60, BRICK),
        ceiling_light("light", 0.0, -0.50, 0.50, 0.10, (12.0, 12.0, 10.0)),
        ceiling_light("light-2", 0.0, 0.50, 0.50, 0.10, (12.0, 10.0, 8.0)),
    ]


def paper_train_5() -> list[Part]:
    """Side colours swapped (green left, red right), grey back wall; one long narrow light; a purple
    cylinder back right, a small box back left, a flat slab in the middle and a sphere front right."""
    return walls(red=GREEN, green=RED, back=GREY) + [
        column("cylinder", 0.55, -0.55, 0.25, 0.60, PURPLE),
        box("small-box", -0.45, -0.45, (0.15, 0.15, 0.15), 20),
        box("slab", 0.10, 0.0, (0.25, 0.12, 0.25), -35),
        sphere("sphere", 0.55, 0.60, 0.20),
        ceiling_light("light", -0.30, 0.0, 0.10, 0.60, (20.0, 18.0, 14.0)),
    ]


def paper_test() -> list[Part]:
    """The held-out scene: `cornell`, a pink back wall and a new sphere at the front left."""
    parts = [Part(p.name, p.mesh, PINK) if p.name == "back" else p for p in cornell()]
    return parts + [sphere("sphere", -0.50, 0.50, 0.22)]


SCENES = {
    "cornell": cornell,
    "paper-train-1": paper_train_1,
    "paper-train-2": paper_train_2,
    "paper-train-3": paper_train_3,
    "paper-train-4": paper_train_4,
    "paper-train-5": paper_train_5,
    "paper-test": paper_test,
}


# ---- checks: a layout is physically sensible before it is written -----------------------------------

def check(name: str, parts: list[Part]) -> None:
    objects = [p for p in parts if p.name not in WALLS and not np.any(p.radiance)]
    for p in parts:
        vertices, faces = p.mesh
        normals = np.cross(*(vertices[faces[:, k]] - vertices[faces[:, 0]] for k in (1, 2)))
        centroids = vertices[faces].mean(axis=1)
        if p.name in WALLS:  # the box centre is the origin: walls face it
            assert np.all(np.einsum("ij,ij->i", normals, -centroids) > 0), f"{name}/{p.name} faces out"
        elif np.any(p.radiance):
            assert np.all(normals[:, 1] < 0) and np.allclose(normals[:, [0, 2]], 0), f"{name}/{p.name}"
        else:  # closed object: positive signed volume means the faces point outwards
            volume = np.einsum("ij,ij->i", vertices[faces[:, 0]], np.cross(
                vertices[faces[:, 1]], vertices[faces[:, 2]])).sum()
            assert volume > 0, f"{name}/{p.name} faces inwards"
            lo, hi = vertices.min(axis=0), vertices.max(axis=0)
            assert np.all(lo[[0, 2]] > -1) and np.all(hi[[0, 2]] < 1) and hi[1] < LIGHT_Y, \
                f"{name}/{p.name} leaves the box"
    for i, a in enumerate(objects):
        for b in objects[i + 1:]:
            assert not overlap(a.mesh[0], b.mesh[0]), f"{name}: {a.name} overlaps {b.name}"


# ---- writing ---------------------------------------------------------------------------------------------

def numbers(values) -> str:
    return " ".join(f"{v:.7f}".rstrip("0").rstrip(".") for v in np.round(np.asarray(values, float), 7) + 0.0)


def write_scene(name: str, parts: list[Part], out: Path = OUT) -> None:
    header = f"# {name}: generated by assets/make_scenes.py; edit that script, not this file\n"
    obj, mtl = [header, f"mtllib {name}.mtl\n"], [header]
    first = 1
    for p in parts:
        vertices, faces = p.mesh
        obj.append(f"\ng {p.name}\nusemtl {p.name}\n")
        obj += [f"v {numbers(v)}\n" for v in vertices]
        obj += [f"f {' '.join(str(i) for i in f + first)}\n" for f in faces]
        first += len(vertices)
        mtl.append(f"\nnewmtl {p.name}\nKd {numbers(p.albedo)}\nKe {numbers(p.radiance)}\n")
    (out / f"{name}.obj").write_text("".join(obj))
    (out / f"{name}.mtl").write_text("".join(mtl))
    (out / f"{name}.json").write_text(json.dumps({"camera": CAMERA}, indent=2) + "\n")


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    for name, build in SCENES.items():
        parts = build()
        check(name, parts)
        write_scene(name, parts)
        print(f"{OUT / name}.obj: {sum(len(p.mesh[1]) for p in parts)} triangles, {len(parts)} groups")


if __name__ == "__main__":
    main()
