"""Imports a .usda stage into Blender 4.5 (bpy from PyPI) and prints what Blender made of it.

Usage: .venv/bin/python tests/blender_check.py STAGE.usda [STAGE.usda ...]  (one JSON line each)
Each stage is imported into an empty scene with the importer's defaults. Printed, in Blender's
world (Z-up, metres): every volume object (its grids, loaded from the VDB, and the world
position of each grid's voxel (0, 0, 0) centre), every light (type, world position, power in
W, colour, radius, soft falloff), the scene camera (world position, view and up directions,
vertical field of view) and every mesh (world bounds).
"""
import json
import sys

import bpy
from mathutils import Vector


def vec(v):
    return [float(c) for c in v]


def check(path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    result = bpy.ops.wm.usd_import(filepath=path)
    out = {"result": sorted(result), "volumes": {}, "lights": {}, "meshes": {}, "camera": None}
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for obj in bpy.context.scene.objects:
        m = obj.matrix_world
        if obj.type == "VOLUME":
            grids = obj.data.grids
            grids.load()
            out["volumes"][obj.name] = {
                "filepath": bpy.path.abspath(obj.data.filepath),
                "error": grids.error_message,
                "grids": {
                    g.name: {"matrix_object": [vec(r) for r in g.matrix_object]} for g in grids
                },
                "matrix_world": [vec(r) for r in m],
            }
        elif obj.type == "LIGHT":
            d = obj.data
            out["lights"][obj.name] = {
                "type": d.type,
                "position": vec(m.translation),
                "energy": float(d.energy),
                "color": vec(d.color),
                "radius": float(getattr(d, "shadow_soft_size", 0.0)),
                "soft_falloff": bool(getattr(d, "use_soft_falloff", False)),
            }
        elif obj.type == "CAMERA":
            cam = obj.data
            r = m.to_3x3()
            scene = bpy.context.scene
            out["camera"] = {
                "name": obj.name,
                "is_scene_camera": scene.camera == obj,
                "position": vec(m.translation),
                "forward": vec((r @ Vector((0, 0, -1))).normalized()),
                "up": vec((r @ Vector((0, 1, 0))).normalized()),
                "sensor_fit": cam.sensor_fit,
                "angle_x_deg": float(cam.angle_x) * 180.0 / 3.141592653589793,
                "angle_y_deg": float(cam.angle_y) * 180.0 / 3.141592653589793,
                "lens": float(cam.lens),
                "sensor_width": float(cam.sensor_width),
                "sensor_height": float(cam.sensor_height),
            }
        elif obj.type == "MESH":
            ev = obj.evaluated_get(depsgraph)
            pts = [m @ v.co for v in ev.data.vertices]
            out["meshes"][obj.name] = {
                "min": [min(p[a] for p in pts) for a in range(3)],
                "max": [max(p[a] for p in pts) for a in range(3)],
            }
    return out


for path in sys.argv[1:]:
    print(json.dumps(check(path)))
