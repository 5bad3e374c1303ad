//! KTX2 export: randomized volumes written as R16F and R8 3D textures, parsed back by the
//! `ktx2` crate and compared texel by texel; the Bevy FogVolume snippet; errors on bad input.

mod common;
use common::Rng;

use fogsmith::export::ktx::{fog_volume_snippet, r8_texel, write_ktx2, Ktx2Format};
use fogsmith::scene::{GridSpec, Medium, Volume};
use glam::{UVec3, Vec3};

/// A random grid (non-cubic resolution and cells) with exact zeros, tiny and large values.
fn random_volume(seed: u64) -> Volume {
    let mut r = Rng(fogsmith::rng::scrambled(seed));
    let res = UVec3::new(1 + (r.f32() * 20.0) as u32, 1 + (r.f32() * 20.0) as u32, 1 + (r.f32() * 20.0) as u32);
    let min = Vec3::new(r.f32() * 4.0 - 2.0, r.f32() * 4.0 - 2.0, r.f32() * 4.0 - 2.0);
    let max = min + Vec3::new(0.1 + r.f32() * 3.0, 0.1 + r.f32() * 3.0, 0.1 + r.f32() * 3.0);
    let grid = GridSpec { min, max, resolution: res };
    let peak = [1e-3, 1.0, 37.0, 6.0e4][(seed % 4) as usize];
    let data = (0..grid.cell_count())
        .map(|_| {
            let u = r.f32();
            if u < 0.3 {
                0.0
            } else {
                peak * r.f32().powi(3)
            }
        })
        .collect();
    Volume::new(grid, data)
}

fn kv(reader: &ktx2::Reader<Vec<u8>>, key: &str) -> String {
    let v = reader.key_value_data().find(|(k, _)| *k == key).unwrap_or_else(|| panic!("no key {key}")).1;
    String::from_utf8(v.strip_suffix(&[0]).unwrap_or(v).to_vec()).unwrap()
}

#[test]
fn every_texel_reads_back_with_the_ktx2_crate() {
    let dir = common::temp_dir();
    for seed in 1..=12u64 {
        let vol = random_volume(seed);
        let r = vol.grid.resolution;
        for format in [Ktx2Format::R16f, Ktx2Format::R8] {
            let path = dir.path().join(format!("{seed}_{format:?}.ktx2"));
            let info = write_ktx2(&path, &vol, format).unwrap();
            let bytes = std::fs::read(&path).unwrap();
            assert_eq!(bytes.len() as u64, info.bytes);
            let reader = ktx2::Reader::new(bytes)
                .unwrap_or_else(|e| panic!("seed {seed} {format:?}: ktx2 rejects the file: {e:?}"));
            let h = reader.header();
            let (want_format, texel_bytes) = match format {
                Ktx2Format::R16f => (ktx2::Format::R16_SFLOAT, 2),
                Ktx2Format::R8 => (ktx2::Format::R8_UNORM, 1),
            };
            assert_eq!(h.format, Some(want_format));
            assert_eq!((h.pixel_width, h.pixel_height, h.pixel_depth), (r.x, r.y, r.z), "seed {seed}");
            assert_eq!((h.layer_count, h.face_count, h.level_count), (0, 1, 1));
            assert_eq!(h.supercompression_scheme, None);
            // The data format descriptor is the one the crate builds for the format.
            let (basic, type_size) = ktx2::dfd::Basic::from_format(want_format).unwrap();
            assert_eq!(h.type_size, type_size);
            assert_eq!(reader.basic_dfd(), Some(&basic), "seed {seed} {format:?}");
            assert_eq!(kv(&reader, "KTXorientation"), "ruo");
            assert!(kv(&reader, "KTXwriter").starts_with("fogsmith"));
            assert_eq!(kv(&reader, "fogsmith.quantity"), "extinction 1/m");
            let scale: f32 = kv(&reader, "fogsmith.scale").parse().unwrap();
            assert_eq!(scale, info.scale);
            let g = |s: String| s.split(' ').map(|c| c.parse::<f32>().unwrap()).collect::<Vec<_>>();
            assert_eq!(g(kv(&reader, "fogsmith.grid_min")), vol.grid.min.to_array());
            assert_eq!(g(kv(&reader, "fogsmith.grid_max")), vol.grid.max.to_array());

            let levels: Vec<_> = reader.levels().collect();
            assert_eq!(levels.len(), 1);
            let data = levels[0].data;
            assert_eq!(data.len(), vol.data.len() * texel_bytes, "seed {seed}");
            // Texel (i, j, k) at (k·h + j)·w + i, as a 3D texture's rows and slices run.
            let max = vol.data.iter().fold(0.0f32, |m, v| m.max(*v));
            for k in 0..r.z {
                for j in 0..r.y {
                    for i in 0..r.x {
                        let v = vol.get(i, j, k);
                        let n = ((k * r.y + j) * r.x + i) as usize;
                        let back = match format {
                            Ktx2Format::R16f => {
                                let t = half::f16::from_le_bytes([data[2 * n], data[2 * n + 1]]);
                                assert_eq!(t, half::f16::from_f32(v), "seed {seed} cell {i} {j} {k}");
                                t.to_f32()
                            }
                            Ktx2Format::R8 => {
                                assert_eq!(data[n], r8_texel(v, scale));
                                data[n] as f32 / 255.0 * scale
                            }
                        };
                        // Rounding error: half a unit in the last place.
                        let tol = match format {
                            Ktx2Format::R16f => (v * 2f32.powi(-11)).max(2f32.powi(-25)),
                            Ktx2Format::R8 => scale / 510.0 * 1.0001,
                        };
                        assert!((back - v).abs() <= tol, "seed {seed} {format:?} cell {i} {j} {k}: {back} vs {v}");
                    }
                }
            }
            match format {
                Ktx2Format::R16f => assert_eq!(scale, 1.0),
                Ktx2Format::R8 => assert_eq!(scale, if max > 0.0 { max } else { 1.0 }),
            }
        }
    }
}

#[test]
fn bevy_snippet_matches_the_grid() {
    let vol = random_volume(3);
    let medium = Medium { base_extinction: 0.05, albedo: 0.7, anisotropy: 0.3, ..Medium::default() };
    let dir = common::temp_dir();
    let info = write_ktx2(&dir.path().join("d.ktx2"), &vol, Ktx2Format::R8).unwrap();
    let text = fog_volume_snippet(&vol, &medium, &info, "fog/d.ktx2");
    let v: ron::Value = ron::from_str(&text).unwrap_or_else(|e| panic!("the snippet is not RON: {e}\n{text}"));
    let json = serde_json::to_value(&v).unwrap();
    let f = |v: &serde_json::Value| v.as_f64().unwrap() as f32;
    let t = &json["transform"];
    let c = (vol.grid.min + vol.grid.max) * 0.5;
    let s = vol.grid.max - vol.grid.min;
    for a in 0..3 {
        assert!((f(&t["translation"][a]) - c[a]).abs() < 1e-6, "{text}");
        assert!((f(&t["scale"][a]) - s[a]).abs() < 1e-6, "{text}");
    }
    let fv = &json["fog_volume"];
    assert_eq!(f(&fv["density_factor"]), info.scale);
    assert!((f(&fv["scattering"]) - 0.7).abs() < 1e-6 && (f(&fv["absorption"]) - 0.3).abs() < 1e-6, "{text}");
    assert!((f(&fv["scattering_asymmetry"]) - 0.3).abs() < 1e-6);
    assert_eq!(json["density_texture"], "fog/d.ktx2");
    assert!(text.contains("s.is_srgb = false).load(\"fog/d.ktx2\")"), "{text}");
}

#[test]
fn bad_volumes_give_clear_errors() {
    let dir = common::temp_dir();
    let path = dir.path().join("x.ktx2");
    let grid = GridSpec { min: Vec3::ZERO, max: Vec3::ONE, resolution: UVec3::splat(2) };
    for (bad, format, needle) in [
        (f32::NAN, Ktx2Format::R16f, "extinction NaN"),
        (-1.0, Ktx2Format::R8, "extinction -1"),
        (1.0e6, Ktx2Format::R16f, "r8"),
    ] {
        let mut data = vec![0.5; 8];
        data[5] = bad;
        let e = write_ktx2(&path, &Volume::new(grid, data), format).unwrap_err().to_string();
        assert!(e.contains(needle) && e.contains("x.ktx2"), "{bad}: {e}");
        assert!(!path.exists(), "a refused export left a file");
    }
    let e = write_ktx2(&dir.path().join("no-such-dir/x.ktx2"), &Volume::new(grid, vec![0.5; 8]), Ktx2Format::R8)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no-such-dir"), "{e}");
}
