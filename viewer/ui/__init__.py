"""The interactive window's pieces (viewer/app.py puts them together):

options          the viewer's command-line flags (no GL: viewer/cli.py adds them to `view`)
imgui_renderer   imgui draw data -> moderngl (imgui >= 1.92 texture protocol)
imgui_input      window events -> imgui's input queue
controls         input imgui does not want -> camera gestures and hotkeys
camera_controller  orbit / pan / zoom / fly camera
viewport         when and at what resolution the scene is drawn, presenting it
session          the scene shown, the user's edits, loading dropped files
scene_edits      light and material edits applied to the loaded scene
gi_sources       the GI source shown (viewer.sources): restarts and hand-over of probes
live_sources     each GI source's adapter: what it does on a change and in every frame, its status line
compute_source   the paper's kernel on the all-pairs compute-shader solver, stepped every frame
relight_source   the physical kernel's compute source: traced once per geometry, relit after every edit
neural_source    the network, run once the scene's voxels are ready
background       threads and the CPU solver's worker process
frame_graph      CPU and GPU frame times (GL timer queries) and their graph
panels           the imgui windows
unattended       --screenshot, --frames, --quit-after, --bench, --resources, --stats: the window on its own
"""
