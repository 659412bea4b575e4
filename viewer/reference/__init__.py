"""The independent ground truth: Mitsuba 3.

    mitsuba.py     probe SH, irradiance and images rendered by Mitsuba 3 (the face the rest imports)
    conversion.py  a Scene as a Mitsuba scene
    runtime.py     Mitsuba loaded lazily, the variant in use
    cache.py       results cached on disk by scene and settings
"""
