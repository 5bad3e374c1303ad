//! [`BakedFogMaterial`]: a Fogsmith light bake drawn on a unit cube scaled to the grid box.
//!
//! Bevy's `FogVolume` reads one density channel and lights it itself, so it cannot show baked
//! emission. This material marches the box in `baked_fog.wgsl` instead. It draws the cube's
//! back faces, so a camera inside the box still sees the fog in front of it.

use bevy::asset::embedded_asset;
use bevy::mesh::MeshVertexBufferLayoutRef;
use bevy::pbr::{MaterialPipeline, MaterialPipelineKey};
use bevy::prelude::*;
use bevy::reflect::TypePath;
use bevy::render::render_resource::{
    AsBindGroup, Face, RenderPipelineDescriptor, ShaderType, SpecializedMeshPipelineError,
};
use bevy::shader::ShaderRef;

/// Registers the material and its embedded shader.
pub struct BakedFogPlugin;

impl Plugin for BakedFogPlugin {
    fn build(&self, app: &mut App) {
        embedded_asset!(app, "baked_fog.wgsl");
        app.add_plugins(MaterialPlugin::<BakedFogMaterial>::default());
    }
}

/// The shader's uniform; field order and meaning as `BakedFog` in `baked_fog.wgsl`.
#[derive(Clone, Copy, Debug, ShaderType)]
pub struct BakedFogParams {
    pub box_min: Vec3,
    /// W·m⁻³·sr⁻¹ per texel unit of RGB.
    pub emission_scale: f32,
    pub box_max: Vec3,
    /// 1/m per texel unit of A.
    pub extinction_scale: f32,
    /// Ray-march step in metres.
    pub step: f32,
}

/// Emission (RGB) and extinction (A) of a light bake, in an RGBA16F 3D texture.
#[derive(Asset, TypePath, AsBindGroup, Debug, Clone)]
pub struct BakedFogMaterial {
    #[uniform(0)]
    pub params: BakedFogParams,
    #[texture(1, dimension = "3d")]
    #[sampler(2)]
    pub texture: Handle<Image>,
}

impl Material for BakedFogMaterial {
    fn fragment_shader() -> ShaderRef {
        "embedded://fogsmith_bevy_viewer/baked_fog.wgsl".into()
    }

    fn alpha_mode(&self) -> AlphaMode {
        AlphaMode::Premultiplied
    }

    fn enable_prepass() -> bool {
        false
    }

    fn enable_shadows() -> bool {
        false
    }

    fn specialize(
        _pipeline: &MaterialPipeline,
        descriptor: &mut RenderPipelineDescriptor,
        _layout: &MeshVertexBufferLayoutRef,
        _key: MaterialPipelineKey<Self>,
    ) -> Result<(), SpecializedMeshPipelineError> {
        descriptor.primitive.cull_mode = Some(Face::Front);
        Ok(())
    }
}
