"""Renders Fogsmith's light bake with Blender 4.5's Cycles: emission and absorption, no lights.

Usage: .venv/bin/python tests/blender_bake.py STAGE.usda OUT.f32 WIDTH HEIGHT SAMPLES SEED STRENGTH
The stage (exported with --bake-light) is imported as it is and every light is deleted. The
volume gets a Principled Volume with scattering colour black and absorption colour black (so
its extinction is the density), density 1 from the `density` grid (extinction in 1/m), and
emission colour from the `emission` grid through an Attribute node, times STRENGTH (1: Cycles'
volume emission is radiance per metre, as the bake's W·m⁻³·sr⁻¹ is). The world is black; the
volume moves back by half a voxel as in tests/blender_render.py (Cycles samples voxel i at
i + ½). Writes the linear RGB radiance as float32, rows top to bottom, and prints a JSON line.
"""
import json
import sys
import time

import blender_common
import bpy
import numpy as np

stage, out = sys.argv[1], sys.argv[2]
width, height, samples, seed = map(int, sys.argv[3:7])
strength = float(sys.argv[7])

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=stage)
scene = bpy.context.scene

for o in [o for o in scene.objects if o.type == "LIGHT"]:
    bpy.data.objects.remove(o, do_unlink=True)
vol = blender_common.the_volume(scene)
vol.data.grids.load()
names = [g.name for g in vol.data.grids]
assert "emission" in names and "density" in names, f"grids {names}"

tree, pv = blender_common.fog_material(vol, "FogsmithBake", 0.0, 0.0)
pv.inputs["Absorption Color"].default_value = (0.0, 0.0, 0.0, 1.0)
pv.inputs["Emission Strength"].default_value = strength
attr = tree.nodes.new("ShaderNodeAttribute")
attr.attribute_name = "emission"
tree.links.new(attr.outputs["Color"], pv.inputs["Emission Color"])

blender_common.centre_voxels(vol)

scene.camera = [o for o in scene.objects if o.type == "CAMERA"][0]
blender_common.black_world(scene)

blender_common.single_scattering(scene, samples, seed, width, height)
t = time.time()
px = blender_common.render_rgb(scene, out, width, height)
seconds = time.time() - t
np.ascontiguousarray(px).tofile(out)
print(json.dumps({"seconds": seconds, "mean": float(px.mean()), "grids": names}))
