//! Godot 4 files for a light bake: the baked texture as a stacked-slice image that Godot's
//! importer turns into a `Texture3D`, a fog shader that draws it, and a scene with a
//! `FogVolume` of the grid box's size and place.
//!
//! # What is written, for `NAME.tscn`
//!
//! - `NAME.exr`: the RGBA half-float atlas of [`super::exr::write_baked_atlas_exr`] (emission
//!   in RGB, extinction in A, over their scales), with `NAME.exr.import` asking Godot's
//!   `3d_texture` importer for tiles_x × tiles_y slices, uncompressed (VRAM uncompressed keeps
//!   half floats), no mipmaps.
//! - `NAME.gdshader`: `shader_type fog` setting DENSITY to the extinction (1/m), ALBEDO to
//!   black (Godot adds no light of its own) and EMISSION to the emission. Godot multiplies a
//!   fog shader's EMISSION by min(DENSITY, 1) and stores it in 0..4 (R11G11B10), so the shader
//!   divides by min(DENSITY, 1) and applies `emission_gain` (written as 4 over the largest
//!   emission when that exceeds 4, else 1); divide the camera's exposure by the gain to undo it.
//! - `NAME.tscn`: a `FogVolume` (box shape) centred on the grid box, of its size, with a
//!   `ShaderMaterial` using the shader and texture. Paths are relative to the scene.
//!
//! Godot samples the texture at `UVW`, which runs from the box's min to max corner; the atlas
//! has +y up inside each tile (image rows run down) and may hold empty slices after the last,
//! so the shader flips v and scales w by slices / (tiles_x · tiles_y). Godot's fog is drawn on
//! its froxel grid, so the image is as sharp as that grid (Environment's volumetric fog
//! settings), not the bake.

use super::exr::AtlasLayout;
use crate::scene::GridSpec;

/// Godot's `FogVolume` shape enum value for a box.
const FOG_VOLUME_SHAPE_BOX: u32 = 3;
/// The largest emission Godot's fog buffer holds.
const GODOT_EMISSION_MAX: f32 = 4.0;

/// The `.import` file beside the atlas: Texture3D, the atlas's slices, no compression loss.
pub fn import_file(layout: &AtlasLayout, atlas_name: &str) -> String {
    format!(
        "[remap]\n\nimporter=\"3d_texture\"\ntype=\"CompressedTexture3D\"\n\n[deps]\n\nsource_file=\"{atlas_name}\"\n\n\
         [params]\n\ncompress/mode=3\ncompress/high_quality=false\ncompress/lossy_quality=0.7\n\
         compress/hdr_compression=1\ncompress/channel_pack=0\nmipmaps/generate=false\nmipmaps/limit=-1\n\
         slices/horizontal={}\nslices/vertical={}\n",
        layout.tiles_x, layout.tiles_y
    )
}

/// The gain that keeps the emission within Godot's fog buffer (see the module doc).
pub fn emission_gain(max_emission: f32) -> f32 {
    if max_emission > GODOT_EMISSION_MAX {
        GODOT_EMISSION_MAX / max_emission
    } else {
        1.0
    }
}

/// The fog shader (see the module doc).
pub fn shader(layout: &AtlasLayout, scales: [f32; 2], gain: f32) -> String {
    let fill = layout.slices as f32 / (layout.tiles_x * layout.tiles_y) as f32;
    format!(
        "// Fogsmith's light bake in Godot 4's volumetric fog (enable Environment > Volumetric Fog).\n\
         // The texture holds each cell's emitted radiance (RGB, W/(m3 sr)) and extinction (A, 1/m),\n\
         // each over its scale. The fog emits what Fogsmith's lights scattered and absorbs by its\n\
         // extinction; ALBEDO is black, so Godot's lights add nothing on top.\n\
         shader_type fog;\n\n\
         uniform sampler3D bake : filter_linear, repeat_disable;\n\
         uniform float emission_scale = {e:?};\n\
         uniform float extinction_scale = {a:?};\n\
         // Godot keeps fog emission within 0..4: the gain brings the brightest cell there.\n\
         // Divide the camera's exposure by it to see the bake's radiance.\n\
         uniform float emission_gain = {gain:?};\n\
         // Slices over all the atlas's tiles: the last tiles may be empty.\n\
         const float SLICE_FILL = {fill:?};\n\n\
         void fog() {{\n\
         \x20   // Atlas rows run downwards while y runs up.\n\
         \x20   vec4 v = texture(bake, vec3(UVW.x, 1.0 - UVW.y, UVW.z * SLICE_FILL));\n\
         \x20   float density = max(v.a * extinction_scale, 0.0);\n\
         \x20   DENSITY = density;\n\
         \x20   ALBEDO = vec3(0.0);\n\
         \x20   // Godot multiplies EMISSION by min(DENSITY, 1).\n\
         \x20   EMISSION = v.rgb * (emission_scale * emission_gain / max(min(density, 1.0), 1e-3));\n\
         }}\n",
        e = scales[0],
        a = scales[1],
    )
}

/// The scene: one FogVolume of the grid box with the shader and the texture.
pub fn scene(grid: &GridSpec, shader_name: &str, atlas_name: &str) -> String {
    let c = (grid.min + grid.max) * 0.5;
    let s = grid.max - grid.min;
    format!(
        "[gd_scene load_steps=4 format=3]\n\n\
         [ext_resource type=\"Shader\" path=\"{shader_name}\" id=\"1_shader\"]\n\
         [ext_resource type=\"Texture3D\" path=\"{atlas_name}\" id=\"2_bake\"]\n\n\
         [sub_resource type=\"ShaderMaterial\" id=\"ShaderMaterial_bake\"]\n\
         shader = ExtResource(\"1_shader\")\n\
         shader_parameter/bake = ExtResource(\"2_bake\")\n\n\
         [node name=\"FogsmithBake\" type=\"FogVolume\"]\n\
         transform = Transform3D(1, 0, 0, 0, 1, 0, 0, 0, 1, {}, {}, {})\n\
         size = Vector3({}, {}, {})\n\
         shape = {FOG_VOLUME_SHAPE_BOX}\n\
         material = SubResource(\"ShaderMaterial_bake\")\n",
        c.x, c.y, c.z, s.x, s.y, s.z
    )
}
