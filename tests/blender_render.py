"""Renders a Fogsmith USD stage with Blender 4.5's Cycles on the CPU, single scattering only.

Usage: .venv/bin/python tests/blender_render.py STAGE.usda OUT.f32 WIDTH HEIGHT SAMPLES SEED [BOUNCES]
The stage is imported by Fogsmith's Blender add-on alone (integrations/blender), with no
step by hand: it gives the volume a Principled Volume reading the `density` grid (density 1,
colour = the stage's fogsmith:albedo, anisotropy = fogsmith:anisotropy), moves it back by half
a voxel (Cycles samples a VDB's voxel i at i + 1/2, OpenVDB and Fogsmith at i; without the
move the comparison in tests/blender_render.rs sees the fog about half a voxel off) and turns
off the lights' soft falloff. The world is black; volume bounces 0 (single scattering); the
imported camera renders. With BOUNCES, Cycles follows that many volume bounces (multiple
scattering) instead. Writes the linear RGB radiance as float32, rows top to bottom, and
prints a JSON line.
"""
import json
import sys
import time

import blender_common
import numpy as np

stage, out, width, height, samples, seed = sys.argv[1], sys.argv[2], *map(int, sys.argv[3:7])
bounces = int(sys.argv[7]) if len(sys.argv) > 7 else 0

scene = blender_common.import_with_addon(stage)
vol = blender_common.the_volume(scene)
pv = vol.data.materials[0].node_tree.nodes["Principled Volume"]
albedo = pv.inputs["Color"].default_value[0]
anisotropy = pv.inputs["Anisotropy"].default_value
for o in scene.objects:
    if o.type == "LIGHT" and o.data.type in {"POINT", "SPOT"}:
        assert not o.data.use_soft_falloff, f"{o.name} keeps Blender's soft falloff"
assert scene.camera is not None, "the add-on set no camera"

blender_common.black_world(scene)

blender_common.single_scattering(scene, samples, seed, width, height)
if bounces:
    scene.cycles.volume_bounces = bounces
    scene.cycles.max_bounces = bounces + 1
t = time.time()
px = blender_common.render_rgb(scene, out, width, height)
seconds = time.time() - t
np.ascontiguousarray(px).tofile(out)
print(json.dumps({"seconds": seconds, "mean": float(px.mean()), "albedo": albedo, "anisotropy": anisotropy}))
blender_common.finish()
