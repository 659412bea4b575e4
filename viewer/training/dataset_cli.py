"""The dataset command: `python -m viewer.training.dataset` (viewer/training/dataset.py runs `main`).

Apart from the format (viewer/training/dataset.py), because the command drives the generator
(viewer/training/generate.py) and the shards (viewer/training/shards.py), which both write that format.
"""

from __future__ import annotations

import sys

from viewer.errors import one_line
from viewer.reference.mitsuba import ReferenceUnavailable
from viewer.scene import SceneError
from viewer.training import generate, shards
from viewer.scene.obj import write as write_obj
from viewer.training.dataset import PAPER_SCENES, SPLITS, build_parser, make_scene


def _int_list(text: str, flag: str, low: int, high: int) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise SceneError(f"{flag} {text!r}: expected comma-separated integers") from None
    if not values or any(not low <= v <= high for v in values):
        raise SceneError(f"{flag} {text!r}: each value must be between {low} and {high}")
    return values


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if args.dump_obj is not None:
            for i in _int_list(args.indices, "--indices", 0, 10**6):
                scene, _ = make_scene(args.split, i, args.seed, args.ranges)
                write_obj(scene, args.dump_obj / f"{scene.name}.obj")
                print(args.dump_obj / f"{scene.name}.obj")
            return 0
        if args.out is None:
            parser.error("--out is required (or --dump-obj)")
        resolutions = sorted(set(_int_list(args.probes, "--probes", 2, 128)), reverse=True)
        if args.train < 0 or args.val < 0 or args.directions < 16 or args.shard_size < 1:
            raise SceneError("--train and --val must be at least 0, --directions at least 16, "
                             "--shard-size at least 1")
        if (args.workers is not None and args.workers < 1) or args.mitsuba_every < 1 or args.mitsuba_directions < 0:
            raise SceneError("--workers and --mitsuba-every must be at least 1, --mitsuba-directions at least 0")
        if args.truth == "mitsuba" or args.mitsuba_directions:
            from viewer.reference import mitsuba as reference

            reference.variant()  # ReferenceUnavailable says what to install
        splits = [s.strip() for s in args.splits.split(",") if s.strip()]
        if not splits or any(s not in SPLITS for s in splits):
            raise SceneError(f"--splits {args.splits!r}: choose from {', '.join(SPLITS)}")
        settings = shards.Settings(seed=args.seed, ranges=args.ranges, truth=args.truth,
                                   directions=args.directions, probes=tuple(resolutions), voxels=args.voxels,
                                   mitsuba_directions=args.mitsuba_directions, mitsuba_every=args.mitsuba_every,
                                   counts={"paper": len(PAPER_SCENES), "val": args.val, "train": args.train},
                                   shard_size=args.shard_size)
        command = " ".join(["python -m viewer.training.dataset", *(argv if argv is not None else sys.argv[1:])])
        result = generate.run(args.out, settings, splits, workers=args.workers, address=args.address,
                              verify=args.verify, command=command)
    except (SceneError, ReferenceUnavailable) as exc:
        print(f"error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    except OSError as exc:   # --out names a file, a folder it may not write, a full disk
        where = exc.filename if exc.filename is not None else args.out
        print(f"error: {one_line(str(where))}: {one_line(exc.strerror or type(exc).__name__)}", file=sys.stderr)
        return 2
    rate = (f"; {result.rooms_per_hour:.0f} rooms per hour (wall clock, {result.workers} workers)"
            if result.made else "")
    print(f"{args.out}: {result.made} rooms made, {result.skipped} already there{rate}", file=sys.stderr)
    if result.failed:
        print(f"{len(result.failed)} rooms failed (manifest.json says why): {', '.join(result.failed[:10])}",
              file=sys.stderr)
        return 1
    return 0

if __name__ == "__main__":
    sys.exit(main())
