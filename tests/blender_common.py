"""What the Blender checks share: the import through Fogsmith's add-on alone
(integrations/blender/fogsmith_import: material, half-voxel placement, light falloff, frame
rate), a black world, and Cycles set to single scattering with no filtering or clamping, so
its image can be compared pixel for pixel with `fogsmith render`."""

import os
import sys

import bpy
import numpy as np

ADDON_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "integrations", "blender")


def import_with_addon(path, lighting="AUTO"):
    """A factory-fresh scene with `path` imported by the add-on's operator, as a user's
    File > Import > Fogsmith Fog does; fails unless the operator finished."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sys.path.insert(0, ADDON_DIR)
    import fogsmith_import

    fogsmith_import.register()
    result = bpy.ops.import_scene.fogsmith(filepath=path, lighting=lighting)
    assert result == {"FINISHED"}, f"the add-on's import of {path} ended {result}"
    return bpy.context.scene


def finish():
    """Ends the process now that its output is written: bpy 4.5 can hang at interpreter exit
    (a destructor waits on its own file-closing thread), which would stall the test."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def black_world(scene):
    world = bpy.data.worlds.new("Black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world


def single_scattering(scene, samples, seed, width, height):
    """Cycles on the CPU: one bounce of light in the volume, a box filter one pixel wide,
    no denoising, adaptive sampling or clamping; linear 32-bit EXR output."""
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


def render_rgb(scene, path, width, height):
    """Renders the scene's camera to `path`.exr and returns its RGB, top row first."""
    scene.render.filepath = path + ".exr"
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(path + ".exr")
    return np.array(img.pixels[:], dtype=np.float32).reshape(height, width, 4)[::-1, :, :3]


def the_volume(scene):
    """The one volume object the USD import made."""
    vols = [o for o in scene.objects if o.type == "VOLUME"]
    assert len(vols) == 1, f"expected one volume, found {[o.name for o in vols]}"
    return vols[0]
