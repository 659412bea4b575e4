"""The neural GI source: voxels on the probe lattice -> an ONNX network -> a ProbeGrid in one shot.

    encoding.py  the network's inputs: voxels, direct light and its one-bounce gather on the lattice
    direct.py    the direct light at the lattice: emitting patches, their shadows, the sun
    bounce.py    the one-bounce gather (kept per scene across edits)
    encoder.py   the encoding kept per scene and updated after each edit
    lattice.py   what the encoder keeps per geometry and per occluders
    field.py     NeuralField / NeuralGI: the model file, onnxruntime, the card
    domain.py    the domain guard: is this scene like the rooms the network was trained on?
    ranges.py    the ranges of the procedural training rooms (what the guard compares against)
    paper_inputs.py  the paper's network input (voxel list, pooling): its Table 1 families read it
"""
