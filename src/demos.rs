//! The demo projects shipped in `projects/`, embedded so that the editor, the benchmarks and
//! the tests find them wherever the binary runs.

use crate::scene::{parse_project, Project, ProjectError};
use std::path::Path;

/// (name, RON text) of every bundled demo.
pub const DEMOS: [(&str, &str); 5] = [
    ("cornell", include_str!("../projects/cornell.ron")),
    ("cloud", include_str!("../projects/cloud.ron")),
    ("street", include_str!("../projects/street.ron")),
    ("room", include_str!("../projects/room.ron")),
    ("street-wind", include_str!("../projects/street-wind.ron")),
];

/// The demo called `name`, parsed.
pub fn demo(name: &str) -> Result<Project, ProjectError> {
    let text = DEMOS.iter().find(|(n, _)| *n == name).map_or("", |(_, t)| t);
    parse_project(text, Path::new(&format!("projects/{name}.ron")))
}
