"""Renders Fogsmith's light bake with Blender 4.5's Cycles: emission and absorption, no lights.

Usage: .venv/bin/python tests/blender_bake.py STAGE.usda OUT.f32 WIDTH HEIGHT SAMPLES SEED STRENGTH
The stage (exported with --bake-light) is imported by Fogsmith's Blender add-on alone
(integrations/blender): finding the `emission` grid, it gives the volume a Principled Volume
with scattering and absorption colours black (so its extinction is the density), density 1
from the `density` grid, and the `emission` grid through an Attribute node into Emission
Color at the strength the add-on chooses, which must be STRENGTH (1: Cycles' volume emission
is radiance per metre, as the bake's W·m⁻³·sr⁻¹ is); it hides the stage's lights from the
render and moves the volume back by half a voxel (see tests/blender_render.py). The world is
black. Writes the linear RGB radiance as float32, rows top to bottom, and prints a JSON line.
"""
import json
import sys
import time

import blender_common
import numpy as np

stage, out = sys.argv[1], sys.argv[2]
width, height, samples, seed = map(int, sys.argv[3:7])
strength = float(sys.argv[7])

scene = blender_common.import_with_addon(stage)
vol = blender_common.the_volume(scene)
names = [g.name for g in vol.data.grids]
assert "emission" in names and "density" in names, f"grids {names}"
pv = vol.data.materials[0].node_tree.nodes["Principled Volume"]
got = pv.inputs["Emission Strength"].default_value
assert abs(got - strength) < 1e-6, f"the add-on's emission strength is {got}, the measured one {strength}"
assert tuple(pv.inputs["Color"].default_value)[:3] == (0.0, 0.0, 0.0), "the bake's material scatters"
lit = [o.name for o in scene.objects if o.type == "LIGHT" and not o.hide_render]
assert not lit, f"lights {lit} would light the baked fog a second time"

blender_common.black_world(scene)

blender_common.single_scattering(scene, samples, seed, width, height)
t = time.time()
px = blender_common.render_rgb(scene, out, width, height)
seconds = time.time() - t
np.ascontiguousarray(px).tofile(out)
print(json.dumps({"seconds": seconds, "mean": float(px.mean()), "grids": names}))
blender_common.finish()
