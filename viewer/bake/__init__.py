"""Baked probe grids for other tools.

    grid.py  a converged ProbeGrid as a documented .npz (docs/BAKED.md), and reading one back
    dds.py   the indirect light as a DDS volume texture
"""
