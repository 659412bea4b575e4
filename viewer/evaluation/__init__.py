"""What the tools measure with, shared by the benchmark (viewer/bench/) and training (viewer/training/).

    error.py       relative RMSE against a truth, and the public Cornell box scene when it is there
    points.py      the free-space points accuracy is measured at
    truth.py       Mitsuba's incident-radiance SH at points (all the light, or its reflected part), cached
    report.py      tables written into docs/*.md between two marker lines
    procedural.py  random rooms drawn from `Ranges` (viewer/neural/ranges.py): the training data's rooms,
                   and the stability studies' rooms in and out of that distribution
    lights.py      the lights of a procedural room
    frames.py      the walls of a procedural room as frames

Both tools import this package; it imports neither of them.
"""
