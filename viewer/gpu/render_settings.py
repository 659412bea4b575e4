"""How the renderer draws a frame (RenderSettings), and the views and tone curves it knows.

The renderer (viewer/gpu/renderer.py) reads these on every draw, so a UI can change them live; they
are re-exported from there.
"""

from __future__ import annotations

from dataclasses import dataclass

VIEWS = ("final", "direct", "indirect", "albedo", "normals", "voxels", "probes")
TONEMAPS = {"none": 0, "reinhard": 1, "aces": 2}
VOXEL_COLORS = ("albedo", "radiance")
MAX_EXPOSURE = 64.0
"""Stops either way: 2^64 scales any radiance float32 holds to white or black already; NaN and infinity
would give a black picture."""


@dataclass
class RenderSettings:
    """How a frame is drawn; the renderer reads these on every draw, so a UI can change them live."""

    exposure: float = 0.0
    """Exposure in stops (EV): linear radiance is scaled by 2^exposure before the tone curve."""
    tonemap: str = "aces"
    """Tone curve: `aces` (Narkowicz's ACES fit), `reinhard` (x / (1 + x)), or `none` (clamp to [0, 1],
    like an 8-bit Mitsuba image: use it to compare against the reference)."""
    indirect: bool = True
    """Add the probe grid's indirect light (when a grid was given)."""
    probe_normal_offset: float = 0.5
    """Probes are sampled this many probe spacings off the surface along its normal (leak reduction)."""
    probe_plane_falloff: float = 3.0
    """Leak reduction: each of the 8 probes around the sample point weighs exp(this x its distance in
    front of the shaded surface's plane, in probe spacings), besides its trilinear weight and its
    validity (shaders/probe_grid.glsl): a probe one spacing behind another gets e^-3 (5%) of its
    weight, so probes inside the solid behind a face, and those too near a rotated face (they see its
    voxel staircase), fade out smoothly. Against Mitsuba on the boxes' faces: relative RMS error 0.15
    -> 0.09 (cornell); 4 and more crease the faces where the sample point crosses a probe layer.
    0: plain trilinear interpolation (ProbeGrid.irradiance)."""
    light_samples: int = 32
    """Points on the area emitters for direct light; each has a shadow cube, so the penumbra is made of
    this many hard shadows."""
    shadow_tile: int = 256
    """Texels along one face of an emitter sample's shadow cube."""
    shadow_bias: float = 0.5
    """Normal offset of the shadow lookup, in shadow-map texels at the receiver's distance."""
    sun_shadow_size: int = 2048
    """Texels along the sun's shadow map."""
    voxel_color: str = "albedo"
    """`voxels` view: colour cubes by `albedo` or by outgoing `radiance` (when a radiance was given)."""
    probe_radius: float = 0.15
    """`probes` view: sphere radius as a fraction of the probe spacing."""
    interleave: bool = True
    """Interleaved direct light: each pixel of a 2x2 block shades a quarter of the emitter samples and a
    3x3 plane-aware tent filter recombines them (on llvmpipe about 45% less work for the direct light;
    the penumbra gets smoother, shadow edges blur by about a pixel). Applies to the `final` and
    `direct` views of targets without multisampling, with 8 light samples or more, when `baked` is
    off."""
    baked: bool = True
    """`final`, `direct` and `indirect` views: the irradiance is read from a lightmap atlas with one
    bilinear fetch per fragment, instead of summing the emitter samples and interpolating the probe grid
    per fragment. The direct light is baked once per scene and light setting (viewer/gpu/direct_bake.py:
    the same shadows and penumbrae, linear between texels `lightmap_texel` of the scene's size apart), the probe grid once
    per GI update (viewer/gpu/indirect_bake.py) with per-texel probe weights that add the probes'
    visibility to validity and back-face weights (viewer/probes/weights.py). False: the exact per-fragment
    path (direct light summed per fragment, probes interpolated with `probe_normal_offset` and
    `probe_plane_falloff`)."""
    lightmap_texel: float = 0.02 / 2.01
    """Lightmap texel spacing of the baked light, as a fraction of the scene's longest side: 0.02 units
    for the built-in Cornell box (2.01 across), about 100 texels along it, whatever unit a scene is
    modelled in (a room in metres or in centimetres gets the same lightmap). A scene whose atlas would
    pass the texel budget or the GL context's texture size gets coarser texels instead
    (viewer/gpu/direct_bake.py, `fitted_texel`)."""
    lightmap_faces: int = 150_000
    """With `baked`: the most faces a scene may have for its light to be read from lightmaps. Each face
    gets its own tile of at least 3x3 texels and a final-gather sample a side, so a dense scan pays for
    every triangle however small, and past a point its tiles hold less than the probes do. Measured on the
    Cornell box with the Stanford bunny refined to more triangles (the same surface), capture at 640x360
    against Mitsuba's 256 spp render: 28k faces 37.5 dB baked / 36.7 dB per fragment (8.6 / 3.8 s),
    68k 37.3 / 36.7 dB (18.8 / 4.8 s), 272k 36.1 / 36.7 dB (64 / 14 s). A scene with more faces is drawn
    on the per-fragment path, as one past the lightmap's capacity is."""
    final_gather: int = 72
    """With `baked`: rays per lightmap sample of the final gather (viewer/gpu/final_gather.py), which takes each
    sample's indirect light from the direct and probe-lit light that its surroundings reflect, so that
    light the probes cannot resolve (contacts, corners, a face half open to the outside) is right. 2 r^2
    (a full grid of strata: 32, 72, 128, ...); 0: the probes' light alone."""

    def __post_init__(self):
        if not (isinstance(self.exposure, (int, float)) and abs(self.exposure) <= MAX_EXPOSURE):
            raise ValueError(f"exposure must be a number of stops within +-{MAX_EXPOSURE:g}, not {self.exposure!r}")
        if self.tonemap not in TONEMAPS:
            raise ValueError(f"tonemap must be one of {', '.join(TONEMAPS)}, not {self.tonemap!r}")
        if not 0.0 <= self.probe_plane_falloff <= 20.0:
            raise ValueError(f"probe_plane_falloff must be in [0, 20], not {self.probe_plane_falloff}")
        rows = round((self.final_gather / 2) ** 0.5)
        if self.final_gather < 0 or 2 * rows * rows != self.final_gather:
            raise ValueError(f"final_gather must be 0 or 2 r^2 rays (32, 72, 128, ...), not {self.final_gather}")
        if self.voxel_color not in VOXEL_COLORS:
            raise ValueError(f"voxel_color must be one of {', '.join(VOXEL_COLORS)}, not {self.voxel_color!r}")
