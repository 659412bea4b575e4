"""The independent ground truth: Mitsuba 3.

    mitsuba.py  probe SH, irradiance and images rendered by Mitsuba 3
    cache.py    results cached on disk by scene and settings
"""
