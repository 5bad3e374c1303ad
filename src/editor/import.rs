//! File → Import VDB…: pick a float grid of a VDB file and the scale that turns its values
//! into extinction, and make it the project's base volume (one undo step). The preview,
//! the slices and exports then show it, loaded by [`crate::export::load_base_layer`].

use crate::export::vdb_read::{list_vdb_grids, VdbGridInfo};
use crate::scene::BaseVolume;
use std::path::{Path, PathBuf};

/// The import window's state: the file and the artist's choices so far.
pub(crate) struct ImportVdb {
    pub path: PathBuf,
    pub grids: Vec<VdbGridInfo>,
    /// Index into `grids` of the chosen grid.
    pub choice: usize,
    pub scale: f32,
}

impl ImportVdb {
    /// Reads the file's table of contents; an error names the file and what is wrong.
    pub fn open(path: PathBuf) -> Result<Self, String> {
        let grids = list_vdb_grids(&path).map_err(|e| e.to_string())?;
        let Some(first) = grids.iter().position(|g| g.importable) else {
            let found: Vec<String> = grids.iter().map(|g| format!("{} ({})", g.name, g.tree_type)).collect();
            return Err(format!(
                "{}: no float grid to import (found: {}). Export a float density grid from the application that made it",
                path.display(),
                if found.is_empty() { "no grids".to_string() } else { found.join(", ") }
            ));
        };
        let choice = grids.iter().position(|g| g.importable && g.name == "density").unwrap_or(first);
        Ok(Self { path, grids, choice, scale: 1.0 })
    }

    /// The base volume this import sets, with the path relative to `project_file`'s folder
    /// when the VDB lies inside it (so the project and its VDB can move together).
    pub fn base_volume(&self, project_file: Option<&Path>) -> BaseVolume {
        let dir = project_file.and_then(Path::parent).filter(|d| !d.as_os_str().is_empty());
        let path = match dir.and_then(|d| self.path.strip_prefix(d).ok()) {
            Some(rel) => rel.to_path_buf(),
            None => self.path.clone(),
        };
        BaseVolume { path, grid: self.grids[self.choice].name.clone(), scale: self.scale }
    }

    /// Draws the window; returns `Some(true)` when the artist imports, `Some(false)` on Cancel.
    /// With `analytic` (the project's scheme, which integrates only the particles) it says so
    /// before the import, and importing also switches the project to `sweep`.
    pub fn ui(&mut self, ctx: &egui::Context, analytic: bool) -> Option<bool> {
        let mut answer = None;
        egui::Window::new("Import VDB").collapsible(false).resizable(false).show(ctx, |ui| {
            ui.label(self.path.display().to_string());
            egui::Grid::new("import-vdb").num_columns(2).show(ui, |ui| {
                ui.label("grid");
                let selected = &self.grids[self.choice];
                egui::ComboBox::from_id_salt("import-grid").selected_text(&selected.name).show_ui(ui, |ui| {
                    for (i, g) in self.grids.iter().enumerate() {
                        let text = format!("{} ({})", g.name, g.tree_type);
                        ui.add_enabled_ui(g.importable, |ui| ui.selectable_value(&mut self.choice, i, text))
                            .response
                            .on_disabled_hover_text(
                                "Not a float grid: only float and half-float grids import as density",
                            );
                    }
                });
                ui.end_row();
                ui.label("scale");
                ui.add(egui::DragValue::new(&mut self.scale).speed(0.01).range(0.0..=1.0e6).suffix(" 1/m per unit"))
                    .on_hover_text("Extinction σt per unit of the grid's values");
                ui.end_row();
            });
            ui.label(
                "The grid is resampled into the project's grid under the particles; see it in the Slices panel (EV).",
            );
            if analytic {
                ui.colored_label(
                    ui.visuals().warn_fg_color,
                    "The project uses the analytic scheme, which integrates only the particles and cannot \
                     use an imported volume. Importing switches the scheme to sweep.",
                );
            }
            ui.horizontal(|ui| {
                let text = if analytic { "Switch to sweep and import" } else { "Import" };
                if ui.button(text).clicked() {
                    answer = Some(true);
                }
                if ui.button("Cancel").clicked() || ui.input(|i| i.key_pressed(egui::Key::Escape)) {
                    answer = Some(false);
                }
            });
        });
        answer
    }
}
