//! Support shared by the integration tests: randomized scenes and the pipeline that renders
//! them (`scenes`), the headless editor under scripted input (`editor`), and temporary and
//! external files (`files`). A test file includes it with `mod common;`.
// Each test file uses a part of it, through the short paths re-exported here.
#![allow(dead_code, unused_imports)]

pub mod editor;
pub mod files;
pub mod scenes;

pub use files::{read_exr_rgb, read_f32_rgb, root, run_ok, temp_dir, venv_python};
pub use scenes::{homogeneous_scene, pipeline, render_both, small_scene, Lcg, Rng};
