"""Light probes: the ProbeGrid data type (apart from its producers), SH, and the surface weights.

    grid.py     ProbeGrid: M^3 L2-SH probes over the scene bounds, interpolation, validity fill
    sh.py       the real SH basis, projection and irradiance convolution (the conventions)
    weights.py  per-texel probe weights with visibility (DDGI-style), for the renderer's lightmap
"""
