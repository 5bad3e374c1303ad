//! OpenEXR exports: the linear HDR render, the baked grids as slices, and a slice atlas.
//!
//! All three are single-part scan-line files, ZIP-compressed (lossless: values read back
//! bit-exactly), written with the `exr` crate to a temporary file and renamed into place.
//!
//! # Render ([`write_render_exr`])
//!
//! Channels `R`, `G`, `B`, `A`, linear (no tone mapping), f32 or f16 (`half`); row 0 is the
//! top of the image, as given.
//!
//! # Slices ([`write_slices_exr`])
//!
//! One image of `res.x × res.y` pixels holding every quantity at every z-slice as its own
//! layer: channel **`<quantity>.z<kkk>.Y`**, e.g. `density.z000.Y`, `optical_depth_0.z012.Y`
//! (layer `<quantity>.z<kkk>`, one luminance channel `Y`; `kkk` is the slice index k
//! zero-padded to at least 3 digits so that layers sort in slice order). Pixel (x, y) of
//! slice k is cell (i = x, j = res.y − 1 − y, k): the image shows the slice with +y up.
//! Values are exact f32. Header attributes: `fogsmith/grid_min`, `fogsmith/grid_max`
//! (v3f, metres), `fogsmith/resolution` (v3i), `fogsmith/quantities` (comma-separated).
//!
//! # Atlas ([`write_atlas_exr`])
//!
//! The extinction as a 2D atlas of its z-slices, the layout game engines import as volume
//! textures (pseudo-volume / flipbook): `tiles_x = ⌈√res.z⌉`, `tiles_y = ⌈res.z / tiles_x⌉`,
//! slice k in tile (k mod tiles_x, k div tiles_x), tile (0, 0) at the top-left; inside a tile
//! the slice is laid out as in the slices file (+y up). Unused tiles are 0. One channel `Y`,
//! f32. Header attributes: `fogsmith/atlas_tiles` (v2i: tiles_x, tiles_y),
//! `fogsmith/atlas_tile_size` (v2i: res.x, res.y), `fogsmith/atlas_slices` (int: res.z),
//! `fogsmith/grid_min`, `fogsmith/grid_max`, `fogsmith/resolution` (in Fogsmith's frame); the
//! same as [`AtlasLayout`], which is returned for the CLI to print. The export frame
//! ([`super::frame`]) is recorded as `fogsmith/up_axis` (text "Y" or "Z"),
//! `fogsmith/meters_per_unit` (double), `fogsmith/handedness` (text "right" or "left") and
//! `fogsmith/index_to_world` (m44f, row vectors as in the VDB: `[i j k 1] · A` is the centre of
//! cell (i, j, k) in the export frame).
//!
//! With a light bake ([`write_baked_atlas_exr`]) the atlas is RGBA half floats: emission in
//! RGB, extinction in A, each over the scale in `fogsmith/emission_scale` and
//! `fogsmith/extinction_scale`.

use super::frame::Frame;
use super::{write_atomic, ExportError};
use crate::scene::{GridSpec, Volume, Volume3};
use exr::prelude::*;
use std::path::Path;

/// Writes a linear RGBA image (row 0 at the top) as f32, or f16 when `half`.
pub fn write_render_exr(
    path: &Path,
    width: usize,
    height: usize,
    rgba: &[[f32; 4]],
    half: bool,
) -> std::result::Result<(), ExportError> {
    if width == 0 || height == 0 || rgba.len() != width.saturating_mul(height) {
        return Err(ExportError::invalid(
            path,
            format!("the image is {width}×{height} but has {} pixels", rgba.len()),
            "pass width × height RGBA pixels",
        ));
    }
    if half {
        let flat: Vec<f32> = rgba.iter().flatten().copied().collect();
        super::vdb::check_half_range(path, "the render", &flat, "write a full-float EXR (no half option)")?;
    }
    let px = |x: usize, y: usize| rgba[y * width + x];
    write_atomic(path, |tmp| {
        let result = if half {
            let channels = SpecificChannels::rgba(|Vec2(x, y)| {
                let p = px(x, y);
                (f16::from_f32(p[0]), f16::from_f32(p[1]), f16::from_f32(p[2]), f16::from_f32(p[3]))
            });
            Image::from_layer(Layer::new(
                (width, height),
                LayerAttributes::default(),
                Encoding::SMALL_LOSSLESS,
                channels,
            ))
            .write()
            .to_file(tmp)
        } else {
            let channels = SpecificChannels::rgba(|Vec2(x, y)| {
                let p = px(x, y);
                (p[0], p[1], p[2], p[3])
            });
            Image::from_layer(Layer::new(
                (width, height),
                LayerAttributes::default(),
                Encoding::SMALL_LOSSLESS,
                channels,
            ))
            .write()
            .to_file(tmp)
        };
        result.map_err(|e| exr_error(path, e))
    })
}

/// The digits of a slice index in channel names: at least 3.
pub fn slice_digits(slices: u32) -> usize {
    slices.saturating_sub(1).to_string().len().max(3)
}

/// The channel name of quantity `name` at slice `k` in [`write_slices_exr`]'s file.
pub fn slice_channel_name(name: &str, k: u32, slices: u32) -> String {
    format!("{name}.z{k:0width$}.Y", width = slice_digits(slices))
}

/// Writes every volume's z-slices into one multi-layer EXR (see the module doc for the
/// naming). All volumes must share one grid.
pub fn write_slices_exr(path: &Path, volumes: &[(&str, &Volume)]) -> std::result::Result<(), ExportError> {
    let Some((_, first)) = volumes.first() else {
        return Err(ExportError::invalid(path, "no volume to export", "pass at least one volume"));
    };
    let grid = first.grid;
    for (n, (name, v)) in volumes.iter().enumerate() {
        check_name(path, name)?;
        if v.grid != grid || v.data.len() as u64 != grid.cell_count() {
            return Err(ExportError::invalid(
                path,
                format!("volume {name:?} is not on the same grid as {:?}", volumes[0].0),
                "export volumes baked on one grid",
            ));
        }
        if volumes[..n].iter().any(|(o, _)| o == name) {
            return Err(ExportError::invalid(
                path,
                format!("two volumes are named {name:?}"),
                "give each quantity a unique name",
            ));
        }
    }
    let [nx, ny, nz] = grid.resolution.to_array().map(|c| c as usize);
    check_size(path, nx, ny)?;
    let mut list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
    for (name, v) in volumes {
        for k in 0..nz {
            let mut samples = Vec::with_capacity(nx * ny);
            for y in 0..ny {
                let j = ny - 1 - y;
                let row = (j + ny * k) * nx;
                samples.extend_from_slice(&v.data[row..row + nx]);
            }
            let channel = slice_channel_name(name, k as u32, nz as u32);
            let text = Text::new_or_none(&channel).ok_or_else(|| {
                ExportError::invalid(
                    path,
                    format!("channel name {channel:?} is not valid in EXR"),
                    "use short ASCII names",
                )
            })?;
            list.push(AnyChannel::new(text, FlatSamples::F32(samples)));
        }
    }
    let mut attributes = LayerAttributes::default();
    grid_attributes(&mut attributes, &grid);
    let names: Vec<&str> = volumes.iter().map(|(n, _)| *n).collect();
    attributes
        .other
        .insert(Text::new_or_panic("fogsmith/quantities"), AttributeValue::Text(text_or_empty(&names.join(","))));
    let layer = Layer::new((nx, ny), attributes, Encoding::SMALL_LOSSLESS, AnyChannels::sort(list));
    write_atomic(path, |tmp| Image::from_layer(layer).write().to_file(tmp).map_err(|e| exr_error(path, e)))
}

/// How [`write_atlas_exr`] laid the slices out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AtlasLayout {
    pub tiles_x: u32,
    pub tiles_y: u32,
    /// Size of one tile (one slice) in pixels: res.x × res.y.
    pub tile_width: u32,
    pub tile_height: u32,
    /// Number of slices (res.z); the last tiles_x·tiles_y − slices tiles are empty.
    pub slices: u32,
    /// Whole image size in pixels.
    pub width: u32,
    pub height: u32,
}

impl AtlasLayout {
    /// The layout for a grid of `res` cells.
    pub fn for_resolution(res: [u32; 3]) -> Self {
        let slices = res[2].max(1);
        let mut tiles_x = (slices as f64).sqrt().ceil() as u32;
        while tiles_x.saturating_mul(tiles_x) < slices {
            tiles_x += 1;
        }
        while tiles_x > 1 && (tiles_x - 1).saturating_mul(tiles_x - 1) >= slices {
            tiles_x -= 1;
        }
        let tiles_y = slices.div_ceil(tiles_x);
        Self {
            tiles_x,
            tiles_y,
            tile_width: res[0],
            tile_height: res[1],
            slices,
            width: tiles_x * res[0],
            height: tiles_y * res[1],
        }
    }
    /// Top-left pixel of slice k's tile.
    pub fn tile_origin(&self, k: u32) -> (u32, u32) {
        ((k % self.tiles_x) * self.tile_width, (k / self.tiles_x) * self.tile_height)
    }
}

impl std::fmt::Display for AtlasLayout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} slices of {}×{} in {}×{} tiles ({}×{} pixels), slice k at tile (k % {}, k / {}) from the top left",
            self.slices,
            self.tile_width,
            self.tile_height,
            self.tiles_x,
            self.tiles_y,
            self.width,
            self.height,
            self.tiles_x,
            self.tiles_x
        )
    }
}

/// Writes the z-slices of `volume` tiled in a 2D atlas (see the module doc) and returns the
/// layout, which is also stored in the header. The frame attributes name Fogsmith's own frame.
pub fn write_atlas_exr(path: &Path, volume: &Volume) -> std::result::Result<AtlasLayout, ExportError> {
    write_atlas_exr_in_frame(path, volume, &Frame::NATIVE)
}

/// [`write_atlas_exr`] with the frame attributes of `frame`.
pub fn write_atlas_exr_in_frame(
    path: &Path,
    volume: &Volume,
    frame: &Frame,
) -> std::result::Result<AtlasLayout, ExportError> {
    let grid = volume.grid;
    if volume.data.len() as u64 != grid.cell_count() {
        return Err(ExportError::invalid(path, "the volume's data does not match its grid", "pass a complete volume"));
    }
    let layout = AtlasLayout::for_resolution(grid.resolution.to_array());
    let (w, h) = (layout.width as usize, layout.height as usize);
    check_size(path, w, h)?;
    let [nx, ny, nz] = grid.resolution.to_array().map(|c| c as usize);
    let mut samples = vec![0.0f32; w * h];
    for k in 0..nz {
        let (ox, oy) = layout.tile_origin(k as u32);
        for y in 0..ny {
            let j = ny - 1 - y;
            let src = (j + ny * k) * nx;
            let dst = (oy as usize + y) * w + ox as usize;
            samples[dst..dst + nx].copy_from_slice(&volume.data[src..src + nx]);
        }
    }
    let mut attributes = atlas_attributes(&grid, &layout, frame);
    let o = &mut attributes.other;
    o.insert(
        Text::new_or_panic("fogsmith/atlas_tile_size"),
        AttributeValue::IntVec2(Vec2(layout.tile_width as i32, layout.tile_height as i32)),
    );
    o.insert(
        Text::new_or_panic("fogsmith/handedness"),
        AttributeValue::Text(Text::new_or_panic(frame.handedness_name())),
    );
    let mut list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
    list.push(AnyChannel::new(Text::new_or_panic("Y"), FlatSamples::F32(samples)));
    let layer = Layer::new((w, h), attributes, Encoding::SMALL_LOSSLESS, AnyChannels::sort(list));
    write_atomic(path, |tmp| Image::from_layer(layer).write().to_file(tmp).map_err(|e| exr_error(path, e)))?;
    Ok(layout)
}

/// The light bake as an atlas laid out as [`write_atlas_exr`] does: RGBA half floats, the
/// emission (W·m⁻³·sr⁻¹) divided by `fogsmith/emission_scale` in RGB and the extinction (1/m)
/// divided by `fogsmith/extinction_scale` in A (scales from [`super::ktx::half_scale`]).
pub fn write_baked_atlas_exr(
    path: &Path,
    ev: &Volume,
    emission: &Volume3,
    frame: &Frame,
) -> std::result::Result<(AtlasLayout, [f32; 2]), ExportError> {
    let grid = ev.grid;
    if emission.grid != grid || ev.data.len() as u64 != grid.cell_count() || emission.data.len() != ev.data.len() {
        return Err(ExportError::invalid(path, "the extinction and emission grids differ", "bake both on one grid"));
    }
    if ev.data.iter().chain(emission.data.iter().flatten()).any(|v| !v.is_finite()) {
        return Err(ExportError::invalid(path, "the bake holds values that are not finite", "bake a finite scene"));
    }
    let layout = AtlasLayout::for_resolution(grid.resolution.to_array());
    let (w, h) = (layout.width as usize, layout.height as usize);
    check_size(path, w, h)?;
    let scales = [super::ktx::half_scale(emission.max_value()), super::ktx::half_scale(ev.max_value().max(0.0))];
    let [nx, ny, nz] = grid.resolution.to_array().map(|c| c as usize);
    let mut channels = vec![vec![half::f16::ZERO; w * h]; 4];
    for k in 0..nz {
        let (ox, oy) = layout.tile_origin(k as u32);
        for y in 0..ny {
            let j = ny - 1 - y;
            for i in 0..nx {
                let src = i + nx * (j + ny * k);
                let dst = (oy as usize + y) * w + ox as usize + i;
                for (c, channel) in channels.iter_mut().enumerate() {
                    let v = if c < 3 { emission.data[src][c] / scales[0] } else { ev.data[src] / scales[1] };
                    channel[dst] = half::f16::from_f32(v);
                }
            }
        }
    }
    let mut attributes = atlas_attributes(&grid, &layout, frame);
    let o = &mut attributes.other;
    o.insert(Text::new_or_panic("fogsmith/emission_scale"), AttributeValue::F32(scales[0]));
    o.insert(Text::new_or_panic("fogsmith/extinction_scale"), AttributeValue::F32(scales[1]));
    let mut list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
    for (name, samples) in ["R", "G", "B", "A"].into_iter().zip(channels) {
        list.push(AnyChannel::new(Text::new_or_panic(name), FlatSamples::F16(samples)));
    }
    let layer = Layer::new((w, h), attributes, Encoding::SMALL_LOSSLESS, AnyChannels::sort(list));
    write_atomic(path, |tmp| Image::from_layer(layer).write().to_file(tmp).map_err(|e| exr_error(path, e)))?;
    Ok((layout, scales))
}

/// The header of an atlas: the grid, the tiling and the frame (up axis, units, index to world).
fn atlas_attributes(grid: &GridSpec, layout: &AtlasLayout, frame: &Frame) -> LayerAttributes {
    let mut attributes = LayerAttributes::default();
    grid_attributes(&mut attributes, grid);
    let o = &mut attributes.other;
    o.insert(
        Text::new_or_panic("fogsmith/atlas_tiles"),
        AttributeValue::IntVec2(Vec2(layout.tiles_x as i32, layout.tiles_y as i32)),
    );
    o.insert(Text::new_or_panic("fogsmith/atlas_slices"), AttributeValue::I32(layout.slices as i32));
    o.insert(Text::new_or_panic("fogsmith/up_axis"), AttributeValue::Text(Text::new_or_panic(frame.up_name())));
    o.insert(Text::new_or_panic("fogsmith/meters_per_unit"), AttributeValue::F64(frame.meters_per_unit()));
    let a = super::vdb::index_to_world_matrix(grid, frame);
    let m: [f32; 16] = std::array::from_fn(|n| a[n / 4][n % 4] as f32);
    o.insert(Text::new_or_panic("fogsmith/index_to_world"), AttributeValue::Matrix4x4(m));
    attributes
}

fn grid_attributes(attributes: &mut LayerAttributes, grid: &GridSpec) {
    let o = &mut attributes.other;
    o.insert(Text::new_or_panic("fogsmith/grid_min"), AttributeValue::FloatVec3((grid.min.x, grid.min.y, grid.min.z)));
    o.insert(Text::new_or_panic("fogsmith/grid_max"), AttributeValue::FloatVec3((grid.max.x, grid.max.y, grid.max.z)));
    let r = grid.resolution;
    o.insert(Text::new_or_panic("fogsmith/resolution"), AttributeValue::IntVec3((r.x as i32, r.y as i32, r.z as i32)));
}

fn text_or_empty(s: &str) -> Text {
    Text::new_or_none(s).unwrap_or_else(|| Text::new_or_panic(""))
}

fn check_name(path: &Path, name: &str) -> std::result::Result<(), ExportError> {
    let ok = !name.is_empty()
        && name.len() <= 200
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if ok {
        Ok(())
    } else {
        Err(ExportError::invalid(
            path,
            format!("quantity name {name:?} cannot name an EXR layer"),
            "use letters, digits, '_' or '-'",
        ))
    }
}

fn check_size(path: &Path, w: usize, h: usize) -> std::result::Result<(), ExportError> {
    if w == 0 || h == 0 || w > i32::MAX as usize / 2 || h > i32::MAX as usize / 2 {
        return Err(ExportError::invalid(
            path,
            format!("an image of {w}×{h} pixels cannot be written"),
            "use a grid with a positive, smaller resolution",
        ));
    }
    Ok(())
}

fn exr_error(path: &Path, e: exr::error::Error) -> ExportError {
    match e {
        exr::error::Error::Io(source) => ExportError::Write { path: path.to_path_buf(), source },
        other => ExportError::invalid(path, format!("the EXR encoder failed: {other}"), "report this as a bug"),
    }
}
