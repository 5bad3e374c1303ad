//! EXR exports read back with the `exr` crate and with OpenEXR itself (its Python bindings
//! for values, `exrheader` for the header).

mod common;

use exr::prelude::*;
use fogsmith::export::exr::{slice_channel_name, write_atlas_exr, write_render_exr, write_slices_exr, AtlasLayout};
use fogsmith::scene::{GridSpec, Volume};
use glam::{UVec3, Vec3};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn tests_dir() -> PathBuf {
    common::root().join("tests")
}

/// The project's validator venv, whose OpenEXR bindings read every export back. A machine
/// without them fails loudly: `./setup.sh` installs them.
fn openexr_python() -> PathBuf {
    let py = common::root().join(".venv/bin/python");
    let ok = Command::new(&py)
        .args(["-c", "import OpenEXR; OpenEXR.File"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    assert!(ok, "{} cannot import OpenEXR: run ./setup.sh (it installs PyPI openexr into .venv)", py.display());
    py
}

fn openexr_read(path: &Path) -> Value {
    let out = Command::new(openexr_python()).arg(tests_dir().join("exr_check.py")).arg(path).output().unwrap();
    assert!(
        out.status.success(),
        "OpenEXR could not read {}: {}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn exrheader(path: &Path) -> String {
    match Command::new("exrheader").arg(path).output() {
        Ok(o) if o.status.success() => String::from_utf8_lossy(&o.stdout).into_owned(),
        Ok(o) => panic!("exrheader failed on {}: {}", path.display(), String::from_utf8_lossy(&o.stderr)),
        Err(e) => panic!("exrheader cannot run ({e}): run ./setup.sh (it installs the Debian package openexr)"),
    }
}

/// Every channel of the file's single layer, read with the exr crate.
fn read_channels(path: &Path) -> (Vec2<usize>, Vec<(String, FlatSamples)>, LayerAttributes) {
    let image = read_all_flat_layers_from_file(path).unwrap();
    assert_eq!(image.layer_data.len(), 1);
    let layer = &image.layer_data[0];
    let channels = layer.channel_data.list.iter().map(|c| (c.name.to_string(), c.sample_data.clone())).collect();
    (layer.size, channels, layer.attributes.clone())
}

fn f32s(s: &FlatSamples) -> Vec<f32> {
    match s {
        FlatSamples::F32(v) => v.clone(),
        other => panic!("expected f32 samples, got {other:?}"),
    }
}

fn test_volume(seed: f32) -> Volume {
    let grid = GridSpec {
        min: Vec3::new(-1.0, 0.0, 2.0),
        max: Vec3::new(2.25, 1.75, 4.75),
        resolution: UVec3::new(13, 7, 11),
    };
    let data =
        (0..grid.cell_count()).map(|n| ((n as f32 * 0.731 + seed).sin() * 3.0).max(0.0) + n as f32 * 1e-3).collect();
    Volume::new(grid, data)
}

#[test]
fn render_exr_float_and_half() {
    let (w, h) = (17usize, 9usize);
    let rgba: Vec<[f32; 4]> =
        (0..w * h).map(|n| [n as f32 * 0.37, 1e-3 * n as f32, 100.0 + n as f32, (n % 5) as f32 * 0.25]).collect();
    let dir = common::temp_dir();
    for half in [false, true] {
        let path = dir.path().join(if half { "render_half.exr" } else { "render.exr" });
        write_render_exr(&path, w, h, &rgba, half).unwrap();
        let (size, channels, _) = read_channels(&path);
        assert_eq!((size.0, size.1), (w, h));
        let names: Vec<&str> = channels.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["A", "B", "G", "R"]);
        let want = |n: usize, c: usize| if half { f16::from_f32(rgba[n][c]).to_f32() } else { rgba[n][c] };
        for (name, samples) in &channels {
            let c = ["R", "G", "B", "A"].iter().position(|x| x == name).unwrap();
            let values: Vec<f32> = match samples {
                FlatSamples::F16(v) if half => v.iter().map(|x| x.to_f32()).collect(),
                FlatSamples::F32(v) if !half => v.clone(),
                other => panic!("{name}: wrong sample type {other:?}"),
            };
            for (n, v) in values.iter().enumerate() {
                assert_eq!(*v, want(n, c), "{name} pixel {n}");
            }
        }
        {
            let header = exrheader(&path);
            assert!(header.contains(if half { "16-bit floating-point" } else { "32-bit floating-point" }), "{header}");
            assert!(header.contains("(0 0) - (16 8)"), "{header}");
        }
        {
            let o = openexr_read(&path);
            assert_eq!(o["size"], serde_json::json!([w, h]));
            for (c, name) in ["R", "G", "B", "A"].iter().enumerate() {
                let ch = &o["channels"][*name];
                assert_eq!(ch["type"], if half { "float16" } else { "float32" });
                let values = ch["values"].as_array().unwrap();
                assert_eq!(values.len(), w * h);
                for (n, v) in values.iter().enumerate() {
                    assert_eq!(v.as_f64().unwrap() as f32, want(n, c), "OpenEXR {name} pixel {n}");
                }
            }
        }
    }
    // A wrong pixel count is refused and leaves nothing behind.
    let path = dir.path().join("bad.exr");
    let err = write_render_exr(&path, w, h + 1, &rgba, false).unwrap_err().to_string();
    assert!(err.contains("bad.exr") && err.contains("pixels"), "{err}");
    assert!(!path.exists());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2, "no temporary files left");
}

#[test]
fn slices_exr_is_exact_with_a_layer_per_quantity_and_slice() {
    let ev = test_volume(0.0);
    let opv = test_volume(1.3);
    let dir = common::temp_dir();
    let path = dir.path().join("slices.exr");
    write_slices_exr(&path, &[("density", &ev), ("optical_depth_0", &opv)]).unwrap();
    let [nx, ny, nz] = ev.dims().map(|c| c as usize);
    let expected = |v: &Volume, k: usize| -> Vec<f32> {
        let mut out = Vec::new();
        for y in 0..ny {
            for i in 0..nx {
                out.push(v.get(i as u32, (ny - 1 - y) as u32, k as u32));
            }
        }
        out
    };
    let (size, channels, attributes) = read_channels(&path);
    assert_eq!((size.0, size.1), (nx, ny));
    assert_eq!(channels.len(), 2 * nz);
    assert_eq!(slice_channel_name("density", 3, 11), "density.z003.Y");
    for (q, v) in [("density", &ev), ("optical_depth_0", &opv)] {
        for k in 0..nz {
            let name = slice_channel_name(q, k as u32, nz as u32);
            let (_, samples) = channels.iter().find(|(n, _)| *n == name).unwrap_or_else(|| panic!("no channel {name}"));
            assert_eq!(f32s(samples), expected(v, k), "{name}");
        }
    }
    let res = attributes.other.get(&Text::from("fogsmith/resolution")).unwrap();
    assert_eq!(*res, AttributeValue::IntVec3((13, 7, 11)));
    {
        let header = exrheader(&path);
        assert!(header.contains("density.z000.Y, 32-bit floating-point"), "{header}");
        assert!(header.contains("optical_depth_0.z010.Y, 32-bit floating-point"), "{header}");
        assert!(header.contains("fogsmith/resolution"), "{header}");
    }
    {
        let o = openexr_read(&path);
        for (q, v) in [("density", &ev), ("optical_depth_0", &opv)] {
            for k in 0..nz {
                let name = slice_channel_name(q, k as u32, nz as u32);
                let values: Vec<f32> = o["channels"][&name]["values"]
                    .as_array()
                    .unwrap_or_else(|| panic!("OpenEXR: no {name}"))
                    .iter()
                    .map(|x| x.as_f64().unwrap() as f32)
                    .collect();
                assert_eq!(values, expected(v, k), "OpenEXR {name}");
            }
        }
    }
}

#[test]
fn atlas_exr_tiles_slices_and_records_the_layout() {
    let ev = test_volume(0.5);
    let dir = common::temp_dir();
    let path = dir.path().join("atlas.exr");
    let layout = write_atlas_exr(&path, &ev).unwrap();
    assert_eq!(
        layout,
        AtlasLayout { tiles_x: 4, tiles_y: 3, tile_width: 13, tile_height: 7, slices: 11, width: 52, height: 21 }
    );
    assert_eq!(AtlasLayout::for_resolution([8, 8, 16]).tiles_x, 4);
    assert_eq!(
        AtlasLayout::for_resolution([8, 8, 17]),
        AtlasLayout { tiles_x: 5, tiles_y: 4, tile_width: 8, tile_height: 8, slices: 17, width: 40, height: 32 }
    );
    let [nx, ny, nz] = ev.dims();
    let expected = |x: usize, y: usize| -> f32 {
        let (tx, ty) = (x / nx as usize, y / ny as usize);
        let k = ty * 4 + tx;
        if k >= nz as usize {
            return 0.0;
        }
        let i = x % nx as usize;
        let j = ny as usize - 1 - y % ny as usize;
        ev.get(i as u32, j as u32, k as u32)
    };
    let (size, channels, attributes) = read_channels(&path);
    assert_eq!((size.0, size.1), (52, 21));
    assert_eq!(channels.len(), 1);
    assert_eq!(channels[0].0, "Y");
    let values = f32s(&channels[0].1);
    for y in 0..21 {
        for x in 0..52 {
            assert_eq!(values[y * 52 + x], expected(x, y), "atlas pixel ({x}, {y})");
        }
    }
    assert_eq!(attributes.other.get(&Text::from("fogsmith/atlas_tiles")), Some(&AttributeValue::IntVec2(Vec2(4, 3))));
    assert_eq!(
        attributes.other.get(&Text::from("fogsmith/atlas_tile_size")),
        Some(&AttributeValue::IntVec2(Vec2(13, 7)))
    );
    assert_eq!(attributes.other.get(&Text::from("fogsmith/atlas_slices")), Some(&AttributeValue::I32(11)));
    {
        let header = exrheader(&path);
        assert!(header.contains("fogsmith/atlas_tiles (type v2i): (4 3)"), "{header}");
        assert!(header.contains("fogsmith/atlas_tile_size (type v2i): (13 7)"), "{header}");
        assert!(header.contains("fogsmith/atlas_slices (type int): 11"), "{header}");
    }
    {
        let o = openexr_read(&path);
        let got: Vec<f32> =
            o["channels"]["Y"]["values"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32).collect();
        assert_eq!(got, values);
        assert!(o["header"]["fogsmith/atlas_tiles"].as_str().unwrap().contains('4'), "{}", o["header"]);
    }
}

/// The atlas header names the export frame, and its index-to-world matrix puts every tile
/// pixel's cell centre where the frame puts it.
#[test]
fn atlas_exr_records_the_export_frame() {
    use fogsmith::export::exr::write_atlas_exr_in_frame;
    use fogsmith::export::frame::{Frame, Handedness, Units, UpAxis};
    let ev = test_volume(0.25);
    let dir = common::temp_dir();
    for up in [UpAxis::Y, UpAxis::Z] {
        for units in [Units::M, Units::Cm] {
            for handedness in [Handedness::Right, Handedness::Left] {
                let frame = Frame { up, units, handedness };
                let path = dir.path().join(format!("atlas_{frame}.exr").replace([' ', ','], "_"));
                write_atlas_exr_in_frame(&path, &ev, &frame).unwrap();
                let (_, _, attributes) = read_channels(&path);
                let get =
                    |k: &str| attributes.other.get(&Text::from(k)).unwrap_or_else(|| panic!("{frame}: no {k}")).clone();
                assert_eq!(get("fogsmith/up_axis"), AttributeValue::Text(Text::from(frame.up_name())), "{frame}");
                assert_eq!(
                    get("fogsmith/handedness"),
                    AttributeValue::Text(Text::from(frame.handedness_name())),
                    "{frame}"
                );
                assert_eq!(get("fogsmith/meters_per_unit"), AttributeValue::F64(frame.meters_per_unit()), "{frame}");
                let AttributeValue::Matrix4x4(m) = get("fogsmith/index_to_world") else {
                    panic!("{frame}: index_to_world is not a m44f")
                };
                let [nx, ny, nz] = ev.dims();
                for (i, j, k) in [(0, 0, 0), (nx - 1, 0, 0), (0, ny - 1, 0), (0, 0, nz - 1), (2, 3, 4)] {
                    let w: Vec<f64> = (0..3)
                        .map(|b| {
                            i as f64 * m[b] as f64
                                + j as f64 * m[4 + b] as f64
                                + k as f64 * m[8 + b] as f64
                                + m[12 + b] as f64
                        })
                        .collect();
                    let c = frame.point(ev.grid.cell_center(i, j, k).to_array().map(f64::from));
                    for b in 0..3 {
                        assert!(
                            (w[b] - c[b]).abs() < 1e-5 * frame.scale() * 5.0,
                            "{frame}: cell ({i}, {j}, {k}) -> {w:?}, want {c:?}"
                        );
                    }
                }
            }
        }
    }
}
