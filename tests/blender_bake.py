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
vols = [o for o in scene.objects if o.type == "VOLUME"]
assert len(vols) == 1, f"expected one volume, found {[o.name for o in vols]}"
vol = vols[0]
vol.data.grids.load()
names = [g.name for g in vol.data.grids]
assert "emission" in names and "density" in names, f"grids {names}"

mat = bpy.data.materials.new("FogsmithBake")
mat.use_nodes = True
nodes = mat.node_tree.nodes
nodes.clear()
pv = nodes.new("ShaderNodeVolumePrincipled")
pv.inputs["Density"].default_value = 1.0
pv.inputs["Density Attribute"].default_value = "density"
pv.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
pv.inputs["Absorption Color"].default_value = (0.0, 0.0, 0.0, 1.0)
pv.inputs["Emission Strength"].default_value = strength
attr = nodes.new("ShaderNodeAttribute")
attr.attribute_name = "emission"
mat.node_tree.links.new(attr.outputs["Color"], pv.inputs["Emission Color"])
outn = nodes.new("ShaderNodeOutputMaterial")
mat.node_tree.links.new(pv.outputs["Volume"], outn.inputs["Volume"])
vol.data.materials.clear()
vol.data.materials.append(mat)

m = vol.data.grids["density"].matrix_object
half_voxel = [0.5 * (m[r][0] + m[r][1] + m[r][2]) for r in range(3)]
vol.location = [vol.location[r] - half_voxel[r] for r in range(3)]

scene.camera = [o for o in scene.objects if o.type == "CAMERA"][0]
world = bpy.data.worlds.new("Black")
world.use_nodes = True
world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
scene.world = world

scene.render.engine = "CYCLES"
c = scene.cycles
c.device = "CPU"
c.samples = samples
c.seed = seed
c.use_denoising = False
c.use_adaptive_sampling = False
c.max_bounces = 1
c.volume_bounces = 0
c.diffuse_bounces = 0
c.glossy_bounces = 0
c.transmission_bounces = 0
c.transparent_max_bounces = 8
c.sample_clamp_direct = 0.0
c.sample_clamp_indirect = 0.0
c.pixel_filter_type = "BOX"
c.filter_width = 1.0
scene.render.resolution_x = width
scene.render.resolution_y = height
scene.render.resolution_percentage = 100
scene.render.film_transparent = False
scene.view_settings.view_transform = "Standard"
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
scene.render.filepath = out + ".exr"

t = time.time()
bpy.ops.render.render(write_still=True)
seconds = time.time() - t
img = bpy.data.images.load(out + ".exr")
px = np.array(img.pixels[:], dtype=np.float32).reshape(height, width, 4)[::-1, :, :3]
np.ascontiguousarray(px).tofile(out)
print(json.dumps({"seconds": seconds, "mean": float(px.mean()), "grids": names}))
