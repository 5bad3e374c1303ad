"""What the Blender checks share: Fogsmith's volume placed on its voxel centres, a black
world, and Cycles set to single scattering with no filtering or clamping, so its image can be
compared pixel for pixel with `fogsmith render`."""

import bpy
import numpy as np


def centre_voxels(vol):
    """Blender puts a VDB voxel's value at its corner, OpenVDB (and Fogsmith) at its centre:
    move the volume back by half a voxel (the density grid's index-to-object matrix)."""
    vol.data.grids.load()
    m = vol.data.grids["density"].matrix_object
    half_voxel = [0.5 * (m[r][0] + m[r][1] + m[r][2]) for r in range(3)]
    vol.location = [vol.location[r] - half_voxel[r] for r in range(3)]


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


def fog_material(vol, name, albedo, anisotropy):
    """A Principled Volume whose density is the `density` grid, the fog's albedo as its
    colour and its g as the anisotropy; returns the node tree, its Principled Volume node."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.clear()
    pv = nodes.new("ShaderNodeVolumePrincipled")
    pv.inputs["Density"].default_value = 1.0
    pv.inputs["Density Attribute"].default_value = "density"
    pv.inputs["Color"].default_value = (albedo, albedo, albedo, 1.0)
    pv.inputs["Anisotropy"].default_value = anisotropy
    outn = nodes.new("ShaderNodeOutputMaterial")
    mat.node_tree.links.new(pv.outputs["Volume"], outn.inputs["Volume"])
    vol.data.materials.clear()
    vol.data.materials.append(mat)
    return mat.node_tree, pv


def hard_point_lights(scene):
    """Point and spot lights without Blender's soft falloff, as Fogsmith's lights are."""
    for o in scene.objects:
        if o.type == "LIGHT":
            o.data.use_soft_falloff = False
