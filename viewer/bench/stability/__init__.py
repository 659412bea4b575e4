"""The stability suite: where each method must hold, and where it is expected to fail, by how much.

    python -m viewer.bench.stability [--quick] [--only NAME ...]

One module per study, each with `run(config) -> StudyResult` and `chart(result, path)`:

- leaking     a wall thinner than a voxel between a lit and a dark room
- energy      albedo up to 0.99: white furnace and a closed lit room
- ringing     a small bright emitter: negative irradiance with and without deringing
- precision   very bright emitters through the renderer's RGBA16F probe textures
- temporal    a light moving along a path: frame-to-frame flicker of the indirect light
- resolution  error against voxel and probe resolution, per scene
- ood         the neural model out of its training distribution: error against distance from it
- sun         sunlight through a window: the sunlight the voxels receive, the solver's error
- inputs      where the network's inputs fail: thin walls, small windows, glowing objects, near-black
              and near-white walls, the network against the solver

The methods compared live in one registry (`methods.METHODS`); `scenes` builds the study scenes.
docs/STABILITY.md holds the results; tests/bench/test_stability.py the properties that must always hold.
"""
