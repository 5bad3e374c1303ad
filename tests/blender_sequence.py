"""Imports an animated Fogsmith USD stage with Blender 4.5 (bpy) and reports what it made of
the animation, then renders chosen frames with Cycles on the CPU (single scattering).

Usage: .venv/bin/python tests/blender_sequence.py STAGE.usda OUT_PREFIX WIDTH HEIGHT SAMPLES FRAME [FRAME ...]
Prints one JSON line: the scene's frame range and fps, the volume's sequence settings
(is_sequence, frame_start, frame_duration) and the file it shows at each rendered frame, the
world position of every light and of the camera at every frame of the stage, and per
rendered frame the mean linear radiance; writes each render as OUT_PREFIX<frame>.f32 (linear
RGB float32, rows top to bottom). The stage is imported by
Fogsmith's Blender add-on alone, as in tests/blender_render.py.
"""
import json
import sys

import blender_common
import bpy
import numpy as np
from pxr import Usd

stage, prefix, width, height, samples = sys.argv[1], sys.argv[2], *map(int, sys.argv[3:6])
render_frames = [int(a) for a in sys.argv[6:]]

scene = blender_common.import_with_addon(stage)
usd_stage = Usd.Stage.Open(stage)
start, end = int(usd_stage.GetStartTimeCode()), int(usd_stage.GetEndTimeCode())

vol = blender_common.the_volume(scene)

out = {
    "scene_frames": [scene.frame_start, scene.frame_end],
    "fps": scene.render.fps / scene.render.fps_base,
    "is_sequence": bool(vol.data.is_sequence),
    "frame_start": vol.data.frame_start,
    "frame_duration": vol.data.frame_duration,
    "filepath": vol.data.filepath,
    "lights": {},
    "camera": [],
    "shown": {},
    "renders": {},
}
for f in range(start, end + 1):
    scene.frame_set(f)
    for o in scene.objects:
        if o.type == "LIGHT":
            out["lights"].setdefault(o.name, []).append(list(o.matrix_world.translation))
    out["camera"].append(list(scene.camera.matrix_world.translation))

blender_common.black_world(scene)
blender_common.single_scattering(scene, samples, 1, width, height)
for f in render_frames:
    scene.frame_set(f)
    vol.data.grids.load()
    out["shown"][str(f)] = bpy.path.abspath(vol.data.grids.frame_filepath)
    path = f"{prefix}{f}"
    px = blender_common.render_rgb(scene, path, width, height)
    np.ascontiguousarray(px).tofile(path + ".f32")
    out["renders"][str(f)] = float(px.mean())
print(json.dumps(out))
blender_common.finish()
