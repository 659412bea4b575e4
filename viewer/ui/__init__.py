"""The interactive window's pieces (viewer/app.py puts them together):

options          the viewer's command-line flags (no GL: viewer/cli.py adds them to `view`)
imgui_renderer   imgui draw data -> moderngl (imgui >= 1.92 texture protocol)
imgui_input      window events -> imgui's input queue
controls         input imgui does not want -> camera gestures and hotkeys
camera_controller  orbit / pan / zoom / fly camera
viewport         when and at what resolution the scene is drawn, presenting it
session          the scene shown, the user's edits, loading dropped files
scene_edits      light and material edits applied to the loaded scene
gi_sources       off / compute solver / CPU solver / neural: restarts and hand-over of probes
background       threads and the CPU solver's worker process
frame_graph      CPU and GPU frame times (GL timer queries) and their graph
panels           the imgui windows
unattended       --screenshot, --frames, --quit-after, --bench, --resources, --stats: the window on its own
"""
