"""Imports a Fogsmith file with the Blender add-on alone and reports what it made.

Usage: .venv/bin/python tests/blender_import.py FILE (a .usda stage or a .vdb, the first of a sequence)
Prints one JSON line: the scene's frame rate and, per volume, its sequence settings, location,
grids, material and the Principled Volume's colour and anisotropy.
"""
import json
import sys

import blender_common

scene = blender_common.import_with_addon(sys.argv[1])
out = {"fps": scene.render.fps / scene.render.fps_base, "volumes": []}
for o in scene.objects:
    if o.type != "VOLUME":
        continue
    pv = o.data.materials[0].node_tree.nodes["Principled Volume"]
    out["volumes"].append(
        {
            "name": o.name,
            "is_sequence": bool(o.data.is_sequence),
            "frame_start": o.data.frame_start,
            "frame_duration": o.data.frame_duration,
            "frame_offset": o.data.frame_offset,
            "location": list(o.location),
            "grids": [g.name for g in o.data.grids],
            "material": o.data.materials[0].name,
            "color": list(pv.inputs["Color"].default_value)[:3],
            "anisotropy": pv.inputs["Anisotropy"].default_value,
        }
    )
print(json.dumps(out))
blender_common.finish()
