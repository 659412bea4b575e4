"""The physical GI solver: geometry traced once, light relit after every edit.

    gi.py          GISettings, PhysicalGI (what an edit re-runs), solve()
    geometry.py    Geometry: the voxel gather rays and the probe rays, traced once per scene
    lightpaths.py  LightPaths (lamps) and SunPaths: which voxels and probes see each emitter
    retrace.py     after a moved lamp or object: trace again only the rays the move can change
    relight.py     the bounces and the probe projection as sparse products (every edit)
    transport.py   the reference numpy solver and the paper's kernel (eq. 23-30)
    work.py        the memory a request's settings ask for, checked before a solve starts
"""
