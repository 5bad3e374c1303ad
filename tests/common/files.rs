//! Files the tests make and read: temporary folders, the project's own folder, the test
//! venv's Python and the commands run with it, and the images those commands write.

/// A fresh temporary folder, removed when the value drops.
pub fn temp_dir() -> tempfile::TempDir {
    tempfile::tempdir().expect("a temporary folder")
}

/// The project's root folder.
pub fn root() -> &'static std::path::Path {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The test venv's Python (./setup.sh), which must import `module`: a missing venv or
/// module fails the test loudly, naming what is missing and the fix.
pub fn venv_python(module: &str) -> std::path::PathBuf {
    let py = root().join(".venv/bin/python");
    let ok = std::process::Command::new(&py)
        .args(["-c", &format!("import {module}")])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    assert!(
        ok,
        "this test needs `{module}` in the project's test venv ({}), which is missing: run ./setup.sh",
        py.display()
    );
    py
}

/// Runs `cmd` and returns its stdout; a failure panics with `what` and its output.
pub fn run_ok(cmd: &mut std::process::Command, what: &str) -> String {
    let out = cmd.output().unwrap_or_else(|e| panic!("{what}: {e}"));
    assert!(
        out.status.success(),
        "{what} failed: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Linear RGB of a `width`×`height` EXR render (R, G and B channels), rows top to bottom.
pub fn read_exr_rgb(path: &std::path::Path, width: usize, height: usize) -> Vec<[f32; 3]> {
    use exr::prelude::read_all_flat_layers_from_file;
    let image = read_all_flat_layers_from_file(path).unwrap();
    let layer = &image.layer_data[0];
    assert_eq!((layer.size.0, layer.size.1), (width, height), "{}", path.display());
    let ch = |name: &str| -> Vec<f32> {
        let c = layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == name)
            .unwrap_or_else(|| panic!("{}: no channel {name}", path.display()));
        c.sample_data.values_as_f32().collect()
    };
    let (r, g, b) = (ch("R"), ch("G"), ch("B"));
    (0..width * height).map(|n| [r[n], g[n], b[n]]).collect()
}

/// RGB from a raw little-endian f32 file of `width`×`height` pixels (the Blender scripts' output).
pub fn read_f32_rgb(path: &std::path::Path, width: usize, height: usize) -> Vec<[f32; 3]> {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(bytes.len(), width * height * 12, "{}", path.display());
    bytes
        .chunks_exact(12)
        .map(|c| [0, 1, 2].map(|i| f32::from_le_bytes(c[4 * i..4 * i + 4].try_into().unwrap())))
        .collect()
}
