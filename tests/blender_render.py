"""Renders a Fogsmith USD stage with Blender 4.5's Cycles on the CPU, single scattering only.

Usage: .venv/bin/python tests/blender_render.py STAGE.usda OUT.f32 WIDTH HEIGHT SAMPLES SEED
The stage is imported as it is; the volume gets a Principled Volume reading the `density` grid
(density 1: extinction in 1/m at object scale 1, colour = the stage's fogsmith:albedo,
anisotropy = fogsmith:anisotropy); lights lose their soft falloff (an exact inverse square);
the world is black; volume bounces 0 (single scattering); the imported camera renders.
Cycles (4.5) samples a VDB grid's voxel i at index position i + ½ rather than at i, OpenVDB's
voxel centre, which Fogsmith's files follow: the volume object is moved back by half a voxel
along each index axis so that both renderers see the same fog (without it, the fog shows
about half a voxel off, which the comparison in tests/blender_render.rs would catch).
Writes the linear RGB radiance as float32, rows top to bottom, and prints a JSON line.
"""
import json
import sys
import time

import blender_common
import bpy
import numpy as np

stage, out, width, height, samples, seed = sys.argv[1], sys.argv[2], *map(int, sys.argv[3:7])

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=stage)
scene = bpy.context.scene

vol = blender_common.the_volume(scene)
# Custom attributes of the Volume prim, which the importer does not map to a material.
from pxr import Usd  # noqa: E402  (bpy ships its own USD; usd-core is in the same venv)

usd_stage = Usd.Stage.Open(stage)
prim = usd_stage.GetPrimAtPath("/World/Fog")
albedo = prim.GetAttribute("fogsmith:albedo").Get()
anisotropy = prim.GetAttribute("fogsmith:anisotropy").Get()

blender_common.fog_material(vol, "FogsmithFog", albedo, anisotropy)

blender_common.centre_voxels(vol)

blender_common.hard_point_lights(scene)
cams = [o for o in scene.objects if o.type == "CAMERA"]
scene.camera = cams[0]

blender_common.black_world(scene)

blender_common.single_scattering(scene, samples, seed, width, height)
t = time.time()
px = blender_common.render_rgb(scene, out, width, height)
seconds = time.time() - t
np.ascontiguousarray(px).tofile(out)
print(json.dumps({"seconds": seconds, "mean": float(px.mean()), "albedo": albedo, "anisotropy": anisotropy}))
