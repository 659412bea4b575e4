"""Out of distribution (pending): the neural field's error against a scene's distance from its training set.

Not measured yet: it needs the trained network, which is being built beside this suite. What the study
is to do, so that whoever ships the model fills this file's `run` and nothing else:

1. Register the network in `viewer.bench.stability.methods.METHODS["neural"]` (one entry).
2. Draw scenes inside and outside the training ranges with `viewer.training.procedural.random_scene(rng,
   name, Ranges(...))`, one axis at a time: shapes (`object_kinds` not trained on), colours (`albedo`,
   `saturation` beyond the trained bounds), light positions and sizes (`light_half_extent`,
   `wall_light_probability`), box proportions (`room_scale` below and above the trained range).
3. Distance from the training set: per axis, how far the drawn value lies outside the trained range, in
   units of that range's width (0 inside); and one overall number, e.g. the distance of the scene's
   network input encoding (`viewer.encoding`) to its nearest training example.
4. Error: relative RMSE against Mitsuba at free-space points (as the other studies), for `neural` and, as
   the yardstick, `physical` (whose error does not depend on the training set).
5. Rows: (axis, distance, method, rel. RMSE); chart: error against distance, one curve per method.

Until then `run` returns a result that says so, and the report keeps the section marked pending.
"""

from __future__ import annotations

from viewer.bench.stability.common import RunConfig, StudyResult
from viewer.bench.stability.methods import METHODS

COLUMNS = [("axis", "axis", "{}"), ("distance", "distance from training", "{:.2f}"), ("method", "method", "{}"),
           ("rmse", "rel. RMSE", "{:.3f}")]
PENDING = ("**Pending**: this study needs the neural model (`METHODS['neural']`); "
           "`viewer.bench.stability.ood.run` will fill this section (see its docstring for what it measures).")


def run(config: RunConfig) -> StudyResult:
    result = StudyResult("ood", COLUMNS)
    reason = "no `neural` method is registered" if "neural" not in METHODS else "the study is not written yet"
    result.notes.append(f"{PENDING} Not run: {reason}.")
    return result


def chart(result: StudyResult, path) -> None:
    """No chart while the study is pending."""
