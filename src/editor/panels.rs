//! The Outliner, Inspector and Stats tabs.

use super::session::NEW_STEP;
use super::state::EditorState;
use super::tools::Hit;
use crate::scene::animation::{Channel, Object, Prop};
use crate::scene::{LightKindChoice, Project, Scheme};
use egui::{Color32, DragValue, Ui};
use glam::Vec3;

// ---------------------------------------------------------------- Outliner

pub(crate) fn outliner(state: &mut EditorState, ui: &mut Ui) {
    let (np, nl) = (state.session.project().particles.len(), state.session.project().lights.len());
    ui.horizontal(|ui| {
        if ui.small_button("Select all").on_hover_text("Ctrl+A").clicked() {
            state.session.select_all();
        }
        if ui.small_button("None").on_hover_text("Esc").clicked() {
            state.session.selection.clear();
        }
    });
    egui::CollapsingHeader::new(format!("Lights ({nl})")).default_open(true).show(ui, |ui| {
        for i in 0..nl {
            row(state, ui, Hit::Light(i));
        }
    });
    egui::CollapsingHeader::new(format!("Particles ({np})")).default_open(true).show(ui, |ui| {
        let rows = if np >= FILTER_FROM { particle_filter(state, ui) } else { None };
        let count = rows.as_ref().map_or(np, |r| r.len());
        let row_h = ui.spacing().interact_size.y;
        // Only the rows in view are laid out, however many particles there are.
        egui::ScrollArea::vertical().auto_shrink([false, false]).show_rows(ui, row_h, count, |ui, range| {
            for k in range {
                row(state, ui, Hit::Particle(rows.as_ref().map_or(k, |r| r[k])));
            }
        });
    });
}

/// Particle lists from this long get a filter above them.
const FILTER_FROM: usize = 1000;

/// The filter row of a long particle list and the particles it keeps (None: no filter).
/// The matches are kept for the project's state and the text: finding them reads every
/// particle's label.
fn particle_filter(state: &EditorState, ui: &mut Ui) -> Option<std::sync::Arc<Vec<usize>>> {
    type Matches = (super::session::Version, String, std::sync::Arc<Vec<usize>>);
    let id = ui.id().with("particle-filter");
    let mut text: String = ui.data_mut(|d| d.get_temp(id)).unwrap_or_default();
    ui.horizontal(|ui| {
        ui.label("Filter");
        ui.text_edit_singleline(&mut text)
            .on_hover_text("Show only the particles whose label (\"Particle #12\" or its name) contains this text");
    });
    ui.data_mut(|d| d.insert_temp(id, text.clone()));
    let needle = text.trim().to_lowercase();
    if needle.is_empty() {
        return None;
    }
    let version = state.content_version();
    let project = state.session.project();
    let cached: Option<Matches> = ui.data_mut(|d| d.get_temp(id.with("matches")));
    let rows = match cached.filter(|(v, t, _)| *v == version && *t == needle) {
        Some((_, _, rows)) => rows,
        None => {
            let rows: Vec<usize> = (0..project.particles.len())
                .filter(|&i| project.particle_label(i).to_lowercase().contains(&needle))
                .collect();
            let rows = std::sync::Arc::new(rows);
            ui.data_mut(|d| d.insert_temp::<Matches>(id.with("matches"), (version, needle, rows.clone())));
            rows
        }
    };
    ui.label(format!("{} of {} shown", rows.len(), project.particles.len()));
    Some(rows)
}

fn item_name(project: &Project, hit: Hit) -> (String, bool) {
    match hit {
        Hit::Particle(i) => (project.particle_label(i), project.particles.get(i).is_some_and(|p| p.hidden)),
        Hit::Light(i) => (project.light_label(i), project.lights.get(i).is_some_and(|l| l.hidden)),
    }
}

fn is_selected(state: &EditorState, hit: Hit) -> bool {
    match hit {
        Hit::Particle(i) => state.session.selection.particles.contains(&i),
        Hit::Light(i) => state.session.selection.lights.contains(&i),
    }
}

fn row(state: &mut EditorState, ui: &mut Ui, hit: Hit) {
    let (name, hidden) = item_name(state.session.project(), hit);
    ui.horizontal(|ui| {
        let mut visible = !hidden;
        if ui
            .checkbox(&mut visible, "")
            .on_hover_text("Visible: untick to hide (kept in the file, contributes nothing)")
            .changed()
        {
            match hit {
                Hit::Particle(i) => state.session.edit_particle(NEW_STEP, i, |q| q.hidden = !visible),
                Hit::Light(i) => state.session.edit_light(NEW_STEP, i, |l| l.hidden = !visible),
            }
        }
        if let Some((h, text)) = &mut state.view.rename {
            if *h == hit {
                let r = ui.text_edit_singleline(text);
                r.request_focus();
                if r.lost_focus() {
                    let committed = ui.input(|i| !i.key_pressed(egui::Key::Escape));
                    let new = text.trim().to_owned();
                    state.view.rename = None;
                    if committed && new != name {
                        let name = (!new.is_empty()).then_some(new);
                        match hit {
                            Hit::Particle(i) => state.session.edit_particle(NEW_STEP, i, |q| q.name = name),
                            Hit::Light(i) => state.session.edit_light(NEW_STEP, i, |l| l.name = name),
                        }
                    }
                }
                return;
            }
        }
        let r = ui
            .selectable_label(is_selected(state, hit), &name)
            .on_hover_text("Click: select · Ctrl-click: toggle · Shift-click: range · double-click: rename");
        if r.double_clicked() {
            state.view.rename = Some((hit, name.clone()));
        } else if r.clicked() {
            let m = ui.input(|i| i.modifiers);
            outliner_click(state, hit, m);
        }
    });
}

fn outliner_click(state: &mut EditorState, hit: Hit, m: egui::Modifiers) {
    let sel = &mut state.session.selection;
    if m.shift {
        if let (Some(Hit::Particle(a)), Hit::Particle(b)) = (state.view.outliner_anchor, hit) {
            sel.particles.extend(a.min(b)..=a.max(b));
            return;
        }
        if let (Some(Hit::Light(a)), Hit::Light(b)) = (state.view.outliner_anchor, hit) {
            sel.lights.extend(a.min(b)..=a.max(b));
            return;
        }
    }
    if !m.command {
        sel.clear();
    }
    let set = match hit {
        Hit::Particle(i) => (&mut sel.particles, i),
        Hit::Light(i) => (&mut sel.lights, i),
    };
    if !set.0.remove(&set.1) {
        set.0.insert(set.1);
    }
    state.view.outliner_anchor = Some(hit);
}

// ---------------------------------------------------------------- Inspector

/// A DragValue bound to a project field: one undo step per drag or typed edit.
fn drag(
    ui: &mut Ui,
    value: f32,
    speed: f64,
    range: std::ops::RangeInclusive<f32>,
    unit: &str,
    tip: &str,
) -> Option<(f32, u64)> {
    let mut v = value;
    let r = ui.add(DragValue::new(&mut v).speed(speed).range(range).suffix(unit).max_decimals(4)).on_hover_text(tip);
    (r.changed() && v != value).then(|| (v, r.id.value()))
}

/// The width three labelled fields of a vector need on one row, points.
const VEC3_ROW_WIDTH: f32 = 3.0 * 84.0;

/// Three fields, x y z, on one row where the panel is wide enough, else one per line (never
/// cut off at the panel's edge).
fn drag_vec3(ui: &mut Ui, value: Vec3, speed: f64, unit: &str, tip: &str) -> Option<(Vec3, u64)> {
    let mut out = None;
    let mut fields = |ui: &mut Ui| {
        for (axis, label) in ["x", "y", "z"].iter().enumerate() {
            ui.horizontal(|ui| {
                ui.label(*label);
                // Within the coordinates a project may hold: an edit is valid as it enters.
                let limit = crate::scene::MAX_COORDINATE;
                if let Some((v, id)) = drag(ui, value[axis], speed, -limit..=limit, unit, tip) {
                    let mut w = value;
                    w[axis] = v;
                    out = Some((w, id));
                }
            });
        }
    };
    if ui.available_width() >= VEC3_ROW_WIDTH {
        ui.horizontal(|ui| fields(ui));
    } else {
        ui.vertical(|ui| fields(ui));
    }
    out
}

/// The key diamond of `channel`, before its field's label: filled when keyed at this frame,
/// hollow when animated, orange while the value is an unkeyed edit, faint when not
/// animated. A click keys the value at this frame, or removes its key here.
fn diamond(state: &mut EditorState, ui: &mut Ui, channel: Channel, name: &str) {
    let p = state.session.project();
    let frame = state.session.frame();
    let keyed = p.has_key(channel, frame);
    let animated = p.is_animated(channel);
    let unkeyed = state.session.unkeyed().contains_key(&channel);
    let size = ui.spacing().interact_size.y * 0.7;
    let (rect, r) = ui.allocate_exact_size(egui::vec2(size, size), egui::Sense::click());
    let label = format!("Key {name}");
    r.widget_info(|| egui::WidgetInfo::labeled(egui::WidgetType::Button, true, &label));
    let key = Color32::from_rgb(240, 200, 60);
    let (fill, stroke) = if unkeyed {
        (None, egui::Stroke::new(1.5, Color32::from_rgb(240, 130, 40)))
    } else if keyed {
        (Some(key), egui::Stroke::new(1.0, Color32::BLACK))
    } else if animated {
        (None, egui::Stroke::new(1.5, key))
    } else {
        (None, egui::Stroke::new(1.0, ui.visuals().weak_text_color()))
    };
    let radius = if r.hovered() { size * 0.5 } else { size * 0.4 };
    super::timeline::paint_diamond(ui, rect.center(), radius, fill, stroke);
    let tip = if keyed {
        format!("{name}: keyed at frame {frame}; click to remove this key")
    } else if unkeyed {
        format!("{name}: changed at frame {frame} without a key (lost when the frame changes); click to key it")
    } else if animated {
        format!("{name}: animated, no key at frame {frame}; click to key it here")
    } else {
        format!("{name}: not animated; click to key it at frame {frame}")
    };
    if r.on_hover_text(tip).clicked() {
        state.session.toggle_key(channel);
    }
}

/// A field's label with its key diamond.
fn keyed_label(state: &mut EditorState, ui: &mut Ui, channel: Channel, name: &str) {
    ui.horizontal(|ui| {
        diamond(state, ui, channel, name);
        ui.label(name);
    });
}

/// The warning that unkeyed edits will not stick, naming them.
pub(crate) fn unkeyed_warning(state: &EditorState, ui: &mut Ui) {
    let unkeyed = state.session.unkeyed();
    if unkeyed.is_empty() {
        return;
    }
    let names: Vec<String> = unkeyed.keys().map(|c| c.to_string()).collect();
    ui.colored_label(
        Color32::from_rgb(240, 130, 40),
        format!(
            "Not keyed: {} changed at frame {} only. Press K or click its diamond to key it; changing the frame drops it (auto-key keys such edits)",
            names.join(", "),
            state.session.frame()
        ),
    );
}

/// The Inspector: its rows scroll, and the notice of unkeyed edits sits in a strip below
/// them, so its coming and going moves no row under the pointer.
pub(crate) fn inspector(state: &mut EditorState, ui: &mut Ui) {
    if !state.session.unkeyed().is_empty() {
        egui::Panel::bottom("inspector-unkeyed").show(ui, |ui| unkeyed_warning(state, ui));
    }
    egui::ScrollArea::vertical().auto_shrink([false, false]).show(ui, |ui| inspector_rows(state, ui));
}

fn inspector_rows(state: &mut EditorState, ui: &mut Ui) {
    egui::CollapsingHeader::new("Selection").default_open(true).show(ui, |ui| selection_inspector(state, ui));
    egui::CollapsingHeader::new("Medium").default_open(true).show(ui, |ui| {
        let m = state.session.project().medium;
        egui::Grid::new("medium").num_columns(2).show(ui, |ui| {
            keyed_label(state, ui, Channel(Object::Medium, Prop::BaseExtinction), "base extinction");
            if let Some((v, t)) =
                drag(ui, m.base_extinction, 0.002, 0.0..=100.0, " 1/m", "Homogeneous fog σt filling all space")
            {
                state.session.edit_medium(t, |m| m.base_extinction = v);
            }
            ui.end_row();
            keyed_label(state, ui, Channel(Object::Medium, Prop::HeightFalloff), "height falloff");
            let tip = "k in base extinction · exp(−k·(y − y₀)): 0 keeps the base fog homogeneous";
            if let Some((v, t)) = drag(ui, m.height_falloff, 0.01, 0.0..=crate::scene::MAX_HEIGHT_FALLOFF, " 1/m", tip)
            {
                state.session.edit_medium(t, |m| m.height_falloff = v);
            }
            ui.end_row();
            keyed_label(state, ui, Channel(Object::Medium, Prop::HeightOrigin), "height origin");
            let limit = crate::scene::MAX_COORDINATE;
            let tip = "y₀: the height at which the base fog has its base extinction";
            if let Some((v, t)) = drag(ui, m.height_origin, 0.01, -limit..=limit, " m", tip) {
                state.session.edit_medium(t, |m| m.height_origin = v);
            }
            ui.end_row();
            ui.label("albedo");
            if let Some((v, t)) = drag(ui, m.albedo, 0.01, 0.0..=1.0, "", "Single-scattering albedo σs/σt") {
                state.session.edit_medium(t, |m| m.albedo = v);
            }
            ui.end_row();
            ui.label("anisotropy g");
            if let Some((v, t)) = drag(
                ui,
                m.anisotropy,
                0.01,
                -0.99..=0.99,
                "",
                "Henyey–Greenstein asymmetry: 0 isotropic, > 0 forward scattering",
            ) {
                state.session.edit_medium(t, |m| m.anisotropy = v);
            }
            ui.end_row();
        });
        noise_inspector(state, ui);
    });
    egui::CollapsingHeader::new("Grid").default_open(true).show(ui, |ui| {
        let g = state.session.project().grid;
        ui.label("min");
        if let Some((v, t)) = drag_vec3(ui, g.min, 0.01, " m", "Lower corner of the baked box") {
            state.session.edit_grid(t, |grid| grid.min = v.min(g.max - Vec3::splat(1e-3)));
        }
        ui.label("max");
        if let Some((v, t)) = drag_vec3(ui, g.max, 0.01, " m", "Upper corner of the baked box") {
            state.session.edit_grid(t, |grid| grid.max = v.max(g.min + Vec3::splat(1e-3)));
        }
        ui.horizontal(|ui| {
            ui.label("resolution");
            let max_edge = state.gpu.as_ref().map_or(512, |g| g.pipeline.context().max_grid_edge().min(1024));
            let mut r = g.resolution.to_array();
            let mut changed = None;
            for v in &mut r {
                let resp =
                    ui.add(DragValue::new(v).range(1..=max_edge).speed(0.5)).on_hover_text("Cells along this axis");
                if resp.changed() {
                    changed = Some(resp.id.value());
                }
            }
            if let Some(t) = changed {
                // A resolution the device cannot hold is not applied: the warning below says why.
                let new = crate::scene::GridSpec { resolution: glam::UVec3::from_array(r), ..g };
                let refused = grid_fit_warning(state, &new, state.session.project().lights.len());
                ui.data_mut(|d| d.insert_temp(egui::Id::new("grid-refused"), refused.clone()));
                if refused.is_none() {
                    state.session.edit_grid(t, |grid| grid.resolution = new.resolution);
                }
            }
        });
        let lights = state.session.project().lights.len();
        let bytes = state.gpu.as_ref().map_or(0, |gpu| {
            let req = crate::gpu::FrameRequest::for_project(state.session.project());
            gpu.pipeline.memory_needed(&g, lights, state.session.project().particles.len(), req.width, req.height)
        });
        ui.label(format!(
            "≈ {} on the GPU ({} cells, {lights} lights)",
            crate::gpu::human_bytes(bytes),
            g.cell_count()
        ))
        .on_hover_text(
            "Extinction volume, optical-depth volumes with their scratch twins and the march's lookup volumes, injection lists and image targets",
        );
        let refused: Option<String> = ui.data(|d| d.get_temp(egui::Id::new("grid-refused"))).flatten();
        if let Some(w) =
            refused.or_else(|| grid_fit_warning(state, &g, lights + 1).map(|w| format!("Adding a light: {w}")))
        {
            ui.colored_label(Color32::from_rgb(230, 160, 60), w);
        }
    });
    egui::CollapsingHeader::new("Render").default_open(true).show(ui, |ui| {
        let r = state.session.project().render;
        let cam = state.session.project().camera;
        egui::Grid::new("render").num_columns(2).show(ui, |ui| {
            ui.label("exposure");
            if let Some((v, t)) =
                drag(ui, r.exposure, 0.02, 0.0..=100.0, "", "Tone mapping: 1 − exp(−exposure · radiance)")
            {
                state.session.set_exposure(t, v);
            }
            ui.end_row();
            ui.label("step factor");
            if let Some((v, t)) = drag(
                ui,
                r.step_factor,
                0.01,
                0.01..=8.0,
                "× cell",
                "Ray-march step as a fraction of the smallest cell edge",
            ) {
                state.session.edit_render(t, |r| r.step_factor = v);
            }
            ui.end_row();
            keyed_label(state, ui, Channel(Object::Camera, Prop::FovYDeg), "field of view");
            if let Some((v, t)) = drag(ui, cam.fov_y_deg, 0.2, 1.0..=170.0, "°", "Vertical field of view of the camera")
            {
                state.session.edit_camera(t, |c| c.fov_y_deg = v);
            }
            ui.end_row();
            keyed_label(state, ui, Channel(Object::Camera, Prop::Position), "camera position");
            let tip = "Where the camera stands; orbiting the view changes it too";
            if let Some((v, t)) = drag_vec3(ui, cam.position, 0.01, " m", tip) {
                // The camera must look somewhere: a position on its target is not applied.
                if v != cam.target {
                    state.session.edit_camera(t, |c| c.position = v);
                }
            }
            ui.end_row();
            keyed_label(state, ui, Channel(Object::Camera, Prop::Target), "camera target");
            if let Some((v, t)) = drag_vec3(ui, cam.target, 0.01, " m", "The point the camera looks at") {
                if v != cam.position {
                    state.session.edit_camera(t, |c| c.target = v);
                }
            }
            ui.end_row();
            ui.label("output size");
            ui.horizontal(|ui| {
                let (mut w, mut h) = (r.width, r.height);
                let a = ui
                    .add(DragValue::new(&mut w).range(1..=16384).suffix(" px"))
                    .on_hover_text("Width of `fogsmith render` images and of the image the Export window renders");
                let b = ui
                    .add(DragValue::new(&mut h).range(1..=16384).suffix(" px"))
                    .on_hover_text("Height of `fogsmith render` images and of the image the Export window renders");
                if a.changed() || b.changed() {
                    let t = if a.changed() { a.id.value() } else { b.id.value() };
                    state.session.edit_render(t, |r| {
                        r.width = w;
                        r.height = h;
                    });
                }
            });
            ui.end_row();
        });
    });
    egui::CollapsingHeader::new("Propagation").default_open(true).show(ui, |ui| {
        use clap::ValueEnum;
        let current = state.session.project().propagation.scheme;
        egui::ComboBox::from_label("scheme").selected_text(current.to_string()).show_ui(ui, |ui| {
            let unsupported = crate::gpu::analytic_unsupported(state.session.project());
            for s in Scheme::value_variants() {
                let usable = *s != Scheme::Analytic || unsupported.is_none();
                let r = ui.add_enabled(usable, egui::Button::selectable(*s == current, s.to_string()));
                let r = match unsupported {
                    Some(what) if !usable => r.on_disabled_hover_text(format!(
                        "Integrates particles and fog in closed form, so it cannot represent {what}, which only the grid holds"
                    )),
                    _ => r,
                };
                if r.clicked() && *s != current {
                    state.session.edit_propagation(NEW_STEP, |p| p.scheme = *s);
                }
            }
        })
        .response
        .on_hover_text("How optical depth towards each light is propagated through the grid");
        if current == Scheme::Sweep {
            let mut refine = state.session.project().propagation.sweep_refine;
            let r = ui.checkbox(&mut refine, "refine thin shadows").on_hover_text(
                "Control the error of the sweep's interpolations: where one cannot follow a shadow (particles a cell or two \
                 wide, noise), take it from farther or integrate the path directly. Off: faster, up to a few 1e-2 off there",
            );
            if r.changed() {
                state.session.edit_propagation(NEW_STEP, |p| p.sweep_refine = refine);
            }
            if refine {
                let mut tolerance = state.session.project().propagation.sweep_tolerance;
                let r = ui
                    .horizontal(|ui| {
                        let label = ui.label("tolerance");
                        ui.add(egui::DragValue::new(&mut tolerance).range(crate::scene::SWEEP_TOLERANCE_RANGE).speed(1e-5).custom_formatter(|v, _| format!("{v:.1e}")))
                            .labelled_by(label.id)
                    })
                    .inner
                    .on_hover_text(
                        "Largest transmittance error accepted per interpolation (default 5e-4); the worst error along a ray is \
                         a small multiple of it. Lower for final bakes, higher for speed",
                    );
                if r.changed() {
                    state.session.edit_propagation(r.id.value(), |p| p.sweep_tolerance = tolerance);
                }
            }
        }
    });
    egui::CollapsingHeader::new("Multiple scattering")
        .default_open(true)
        .show(ui, |ui| multiple_scattering_inspector(state, ui));
}

/// The medium's noise: on/off (remembering the last settings), its four numbers, the
/// note on octaves the grid drops, and the brush's noise toggle.
/// Multiple scattering on or off, and its settings when on, on one (wrapping) row.
fn multiple_scattering_inspector(state: &mut EditorState, ui: &mut Ui) {
    use crate::scene::MultipleScattering;
    let current = state.session.project().medium.multiple_scattering;
    ui.horizontal_wrapped(|ui| {
        let mut on = current.is_some();
        let toggle = ui.checkbox(&mut on, "multiple scattering").on_hover_text(
            "Light scattered more than once inside the grid, solved on a coarse grid: bright, high-albedo fog gets \
             about twice the light of single scattering. Off: single scattering only (files without the setting).",
        );
        if toggle.changed() {
            let value = on.then(MultipleScattering::default);
            state.session.edit_medium(super::session::NEW_STEP, |m| m.multiple_scattering = value);
        }
        let Some(ms) = current else { return };
        let set = |state: &mut EditorState, tag: u64, f: &dyn Fn(&mut MultipleScattering)| {
            state.session.edit_medium(tag, |m| {
                if let Some(ms) = m.multiple_scattering.as_mut() {
                    f(ms);
                }
            })
        };
        let mut orders = ms.orders;
        let r = ui.add(DragValue::new(&mut orders).range(1..=64).speed(0.2).prefix("orders ")).on_hover_text(
            "Scattering orders solved one by one; the rest is the geometric tail of the last two (default 8)",
        );
        if r.changed() && orders != ms.orders {
            set(state, r.id.value(), &|m| m.orders = orders);
        }
        let mut cells = ms.resolution;
        let r = ui.add(DragValue::new(&mut cells).range(4..=128).speed(0.5).prefix("cells ")).on_hover_text(
            "The solver's coarse grid holds at most this many cells cubed: more is slower and resolves sharper light (default 24)",
        );
        if r.changed() && cells != ms.resolution {
            set(state, r.id.value(), &|m| m.resolution = cells);
        }
        let tip = "Strength: a factor on the multiply scattered light, 1 is physical (default 1)";
        let mut strength = ms.strength;
        let r = ui
            .add(DragValue::new(&mut strength).range(0.0..=10.0).speed(0.01).prefix("× ").max_decimals(3))
            .on_hover_text(tip);
        if r.changed() && strength != ms.strength {
            set(state, r.id.value(), &|m| m.strength = strength);
        }
    });
}

fn noise_inspector(state: &mut EditorState, ui: &mut Ui) {
    use crate::scene::{Noise, MAX_NOISE_AMPLITUDE, MAX_NOISE_OCTAVES};
    let project = state.session.project();
    let (noise, grid) = (project.medium.noise, project.grid);
    let remembered = egui::Id::new("noise-off");
    let mut on = noise.is_some();
    let toggle = ui
        .checkbox(&mut on, "noise detail")
        .on_hover_text("Fractal value noise modulating the particles' extinction: σ·max(0, 1 + amplitude·n(x)). Base fog and imported volumes are not modulated.");
    if toggle.changed() {
        let last: Option<Noise> = ui.data(|d| d.get_temp(remembered));
        if let Some(n) = noise {
            ui.data_mut(|d| d.insert_temp(remembered, n));
        }
        let size = grid.size().min_element().max(1e-3);
        let fresh = Noise::new(0.8, 4.0 / size, 4, 1);
        state.session.set_noise(on.then(|| last.unwrap_or(fresh)));
    }
    if let Some(n) = noise {
        egui::Grid::new("noise").num_columns(2).show(ui, |ui| {
            let set = |state: &mut EditorState, tag: u64, f: &dyn Fn(&mut Noise)| state.session.edit_noise(tag, f);
            keyed_label(state, ui, Channel(Object::Medium, Prop::NoiseAmplitude), "amplitude");
            if let Some((v, t)) = drag(
                ui,
                n.amplitude,
                0.01,
                0.0..=MAX_NOISE_AMPLITUDE,
                "",
                "a in max(0, 1 + a·n(x)): 0 leaves the particles smooth, above 1 carves holes",
            ) {
                set(state, t, &|m| m.amplitude = v);
            }
            ui.end_row();
            ui.label("frequency");
            if let Some((v, t)) = drag(
                ui,
                n.frequency,
                0.01,
                1e-3..=1e6,
                " 1/m",
                "Lattice frequency of the first octave: its features are 1/frequency metres",
            ) {
                set(state, t, &|m| m.frequency = v);
            }
            ui.end_row();
            ui.label("octaves");
            let mut o = n.octaves;
            let r = ui
                .add(DragValue::new(&mut o).range(1..=MAX_NOISE_OCTAVES).speed(0.05))
                .on_hover_text("Octaves, each at twice the frequency and half the weight of the one before");
            if r.changed() && o != n.octaves {
                set(state, r.id.value(), &|m| m.octaves = o);
            }
            ui.end_row();
            ui.label("seed");
            let mut s = n.seed;
            let r = ui
                .add(DragValue::new(&mut s).range(0..=u32::MAX).speed(1.0))
                .on_hover_text("Picks another noise pattern");
            if r.changed() && s != n.seed {
                set(state, r.id.value(), &|m| m.seed = s);
            }
            ui.end_row();
        });
        if let Some(note) = n.nyquist_note(&grid) {
            ui.colored_label(Color32::from_rgb(230, 160, 60), note);
        }
    }
    ui.checkbox(&mut state.view.brush.noise, "paint with noise")
        .on_hover_text("Whether particles the Paint brush deposits take the medium's noise (each particle's own switch is in the Selection section)");
}

/// A light's kind (each change one undo step, keeping the grid's centre as brightly lit) and
/// what places and aims that kind: a position, a spot's axis, cone and blend, a sun's
/// direction.
fn light_kind_and_aim(state: &mut EditorState, ui: &mut Ui, i: usize, l: &crate::scene::Light) {
    use crate::scene::LightKind;
    let kind = LightKindChoice::of(&l.kind);
    ui.horizontal(|ui| {
        ui.label("kind");
        for choice in LightKindChoice::ALL {
            let tip = match choice {
                LightKindChoice::Point => "Shines equally in every direction from its position",
                LightKindChoice::Spot => "Shines within a cone around its axis",
                LightKindChoice::Sun => {
                    "Parallel light from far away, along its direction; its intensity is an irradiance"
                }
            };
            if ui.selectable_label(kind == choice, choice.label()).on_hover_text(tip).clicked() && kind != choice {
                state.session.set_light_kind(NEW_STEP, i, choice);
            }
        }
    });
    let id = l.id;
    if kind != LightKindChoice::Sun {
        keyed_label(state, ui, Channel(Object::Light(id), Prop::Position), "position");
        if let Some((v, t)) = drag_vec3(ui, l.position, 0.005, " m", "Position of the light") {
            state.session.edit_light(t, i, |q| q.position = v);
        }
    }
    let direction = match l.kind {
        LightKind::Spot { direction, .. } | LightKind::Directional { direction } => direction,
        LightKind::Point => return,
    };
    let (prop, name) = match kind {
        LightKindChoice::Sun => (Prop::SunDirection, "direction (travel)"),
        _ => (Prop::SpotDirection, "axis"),
    };
    keyed_label(state, ui, Channel(Object::Light(id), prop), name);
    let tip = "Direction the light travels (normalised when used); drag the light in the viewport to aim it";
    if let Some((v, t)) = drag_vec3(ui, direction, 0.01, "", tip) {
        state.session.edit_light(t, i, |q| match &mut q.kind {
            LightKind::Spot { direction, .. } | LightKind::Directional { direction } => *direction = v,
            LightKind::Point => {}
        });
    }
    if let LightKind::Spot { angle_deg, blend, .. } = l.kind {
        egui::Grid::new("spot").num_columns(2).show(ui, |ui| {
            keyed_label(state, ui, Channel(Object::Light(id), Prop::AngleDeg), "angle");
            let tip = "Half-angle of the cone: no light beyond it";
            if let Some((v, t)) = drag(ui, angle_deg, 0.2, 0.1..=90.0, "°", tip) {
                state.session.edit_light(t, i, |q| {
                    if let LightKind::Spot { angle_deg, .. } = &mut q.kind {
                        *angle_deg = v;
                    }
                });
            }
            ui.end_row();
            keyed_label(state, ui, Channel(Object::Light(id), Prop::Blend), "blend");
            let tip = "Fraction of the cone over which the light fades out towards its edge";
            if let Some((v, t)) = drag(ui, blend, 0.005, 0.0..=1.0, "", tip) {
                state.session.edit_light(t, i, |q| {
                    if let LightKind::Spot { blend, .. } = &mut q.kind {
                        *blend = v;
                    }
                });
            }
            ui.end_row();
        });
    }
}

fn selection_inspector(state: &mut EditorState, ui: &mut Ui) {
    let sel = state.session.selection.clone();
    if sel.is_empty() {
        ui.label("Nothing selected. Click in the viewport or the outliner.");
        return;
    }
    if sel.particles.len() == 1 && sel.lights.is_empty() {
        let i = *sel.particles.iter().next().unwrap_or(&0);
        let Some(p) = state.session.project().particles.get(i).cloned() else { return };
        ui.label(state.session.project().particle_label(i));
        let object = Object::Particle(p.id);
        keyed_label(state, ui, Channel(object, Prop::Center), "centre");
        if let Some((v, t)) = drag_vec3(ui, p.center, 0.005, " m", "Centre of the gaussian") {
            state.session.edit_particle(t, i, |q| q.center = v);
        }
        egui::Grid::new("particle").num_columns(2).show(ui, |ui| {
            keyed_label(state, ui, Channel(object, Prop::Radius), "radius");
            if let Some((v, t)) = drag(ui, p.radius, 0.002, 1e-3..=100.0, " m", "r in σ = c·exp(−d²/r²)") {
                state.session.edit_particle(t, i, |q| q.radius = v);
            }
            ui.end_row();
            keyed_label(state, ui, Channel(object, Prop::Density), "density");
            if let Some((v, t)) = drag(ui, p.density, 0.02, 0.0..=1e4, " 1/m", "Peak extinction c") {
                state.session.edit_particle(t, i, |q| q.density = v);
            }
            ui.end_row();
        });
        particles_noise(state, ui, &[i]);
        return;
    }
    if sel.lights.len() == 1 && sel.particles.is_empty() {
        let i = *sel.lights.iter().next().unwrap_or(&0);
        let Some(l) = state.session.project().lights.get(i).cloned() else { return };
        ui.label(state.session.project().light_label(i));
        light_kind_and_aim(state, ui, i, &l);
        let kind = LightKindChoice::of(&l.kind);
        egui::Grid::new("light").num_columns(2).show(ui, |ui| {
            let (label, tip) = match kind {
                LightKindChoice::Sun => ("irradiance", "Irradiance E on a plane facing the sun, before any fog"),
                _ => ("intensity", "Radiant intensity I"),
            };
            keyed_label(state, ui, Channel(Object::Light(l.id), Prop::Intensity), label);
            if let Some((v, t)) = drag(ui, l.intensity, 0.05, 0.0..=1e5, kind.intensity_unit(), tip) {
                state.session.edit_light(t, i, |q| q.intensity = v);
            }
            ui.end_row();
            keyed_label(state, ui, Channel(Object::Light(l.id), Prop::Color), "colour");
            let mut c = l.color.to_array();
            let r = ui.color_edit_button_rgb(&mut c).on_hover_text("Per-channel scale of the intensity (linear RGB)");
            if r.changed() {
                state.session.edit_light(r.id.value(), i, |q| q.color = Vec3::from_array(c));
            }
            ui.end_row();
        });
        return;
    }
    ui.label(format!("{} particles and {} lights selected", sel.particles.len(), sel.lights.len()));
    if !sel.particles.is_empty() {
        let p = state.session.project();
        let n = sel.particles.len() as f32;
        let mean_r = sel.particles.iter().filter_map(|&i| p.particles.get(i)).map(|q| q.radius).sum::<f32>() / n;
        let mean_c = sel.particles.iter().filter_map(|&i| p.particles.get(i)).map(|q| q.density).sum::<f32>() / n;
        egui::Grid::new("multi").num_columns(2).show(ui, |ui| {
            ui.label("mean radius");
            if let Some((v, t)) = drag(
                ui,
                mean_r,
                0.002,
                1e-3..=100.0,
                " m",
                "Scales every selected radius so that their mean becomes this value",
            ) {
                state.session.scale_particles(t, &sel.particles, v / mean_r.max(1e-6), false);
            }
            ui.end_row();
            ui.label("mean density");
            if let Some((v, t)) = drag(
                ui,
                mean_c,
                0.02,
                0.0..=1e4,
                " 1/m",
                "Scales every selected density so that their mean becomes this value",
            ) {
                if mean_c > 0.0 {
                    state.session.scale_particles(t, &sel.particles, (v / mean_c).max(1e-6), true);
                }
            }
            ui.end_row();
        });
        let selected: Vec<usize> = sel.particles.iter().copied().collect();
        particles_noise(state, ui, &selected);
    }
}

/// Whether the medium's noise modulates the particles `indices` (one undo step per click);
/// a mixed selection shows unchecked and is set as a whole.
fn particles_noise(state: &mut EditorState, ui: &mut Ui, indices: &[usize]) {
    let particles = &state.session.project().particles;
    let mut on = indices.iter().filter_map(|&i| particles.get(i)).all(|p| p.noise);
    let tip = if state.session.project().medium.noise.is_some() {
        "Whether the medium's noise modulates this particle"
    } else {
        "Whether the medium's noise modulates this particle (the medium has no noise now: see Medium › noise detail)"
    };
    if ui.checkbox(&mut on, "takes noise").on_hover_text(tip).changed() {
        state.session.edit_particles(indices, |p| p.noise = on);
    }
}

/// Why a scene of grid `grid` with `lights` lights would not fit the GPU, naming the
/// largest resolution of the same proportions that would; None when it fits.
fn grid_fit_warning(state: &EditorState, grid: &crate::scene::GridSpec, lights: usize) -> Option<String> {
    let gpu = state.gpu.as_ref()?;
    let project = state.session.project();
    let req = crate::gpu::FrameRequest::for_project(project);
    let particles = project.particles.len();
    let err = gpu.pipeline.check_sizes(grid, lights, particles, req.width, req.height).err()?;
    let r = grid.resolution;
    let largest = gpu.pipeline.largest_fitting_grid(grid, lights, particles, req.width, req.height);
    Some(match largest {
        Some(m) => format!(
            "{}×{}×{} with {lights} lights would not fit ({err}); the largest that fits is {}×{}×{}",
            r.x, r.y, r.z, m.x, m.y, m.z
        ),
        None => format!("{}×{}×{} with {lights} lights would not fit: {err}", r.x, r.y, r.z),
    })
}

// ---------------------------------------------------------------- Stats

/// The frame on show, playback's rate, which frames the preview's fog and shadows come from
/// when they differ, and unkeyed edits.
fn animation_stats(state: &EditorState, ui: &mut Ui) {
    let Some(a) = state.session.project().animation else { return };
    let frame = state.session.frame();
    ui.label(format!("Frame {frame} of {}–{} at {} fps", a.start, a.end, a.fps));
    if let Some(t) = state.playback_text() {
        ui.label(t);
    }
    if let Some(status) = state.preview_status() {
        let warn = ui.visuals().warn_fg_color;
        if let Some(note) = state.preview_frames_note() {
            ui.colored_label(warn, note).on_hover_text(
                "Propagation has not caught up with the frames shown: the optical depths are an earlier frame's",
            );
        }
        if let Some(fog) = status.shown_frame.filter(|&f| f != frame) {
            ui.colored_label(warn, format!("Preview still shows frame {fog} while frame {frame} renders"));
        }
    }
    unkeyed_warning(state, ui);
    ui.separator();
}

pub(crate) fn stats(state: &mut EditorState, ui: &mut Ui) {
    animation_stats(state, ui);
    match state.view.clock.fps() {
        Some(fps) => ui.label(format!("{fps:.1} frames/s (while redrawing)")),
        None => ui.label("– frames/s (idle)"),
    };
    ui.checkbox(&mut state.view.continuous, "Redraw continuously")
        .on_hover_text("Redraw every frame, to measure the frame rate");
    let Some(gpu) = &state.gpu else {
        ui.label(state.gpu_missing.clone().unwrap_or_default());
        return;
    };
    let ctx = gpu.pipeline.context();
    ui.label(format!("Adapter: {}", ctx.adapter_summary()));
    ui.label(format!(
        "Timestamp queries: {}",
        if ctx.supports_timestamps() { "available" } else { "not available (wall times)" }
    ));
    ui.label(format!(
        "GPU memory (scene): {} live, {} at peak",
        crate::gpu::human_bytes(gpu.pipeline.memory_bytes()),
        crate::gpu::human_bytes(gpu.pipeline.peak_memory_bytes())
    ))
    .on_hover_text("GPU buffers and textures the pipeline holds now, and the most it has held");
    ui.separator();
    ui.label("Last update that ran a stage");
    let r = gpu.report;
    egui::Grid::new("stats-times").striped(true).num_columns(2).show(ui, |ui| {
        for (name, v) in [
            ("inject", r.timings_ms.inject),
            ("propagate", r.timings_ms.propagate),
            ("multiple scattering", r.timings_ms.scatter),
            ("march", r.timings_ms.march),
        ] {
            ui.label(name);
            ui.label(if v > 0.0 { format!("{v:.2} ms") } else { "skipped".into() });
            ui.end_row();
        }
    });
    ui.label(format!("Last update: {:.1} ms wall", gpu.update_ms))
        .on_hover_text("All work items and waits of the last frame's pipeline call");
    if let Some((frame, rest)) = gpu.frame_ms {
        let budget = match gpu.budget_ms {
            Some((ms, true)) => format!("{ms:.0} ms budget (idle)"),
            Some((ms, false)) => format!("{ms:.0} ms budget"),
            None => "no budget (wait for full)".into(),
        };
        ui.label(format!(
            "Frame: {frame:.1} ms = {:.1} ms pipeline + {rest:.1} ms UI and present; {budget}",
            frame - rest
        ))
        .on_hover_text(
            "Where the last frame's wall time went: the pipeline's work items (with the quick image), and \
                 everything else (egui's layout and painting, presenting). While no input arrives the budget \
                 grows with the rest of the frame, so most of the time goes to the work.",
        );
    }
    let p = gpu.progress;
    let stage = match p.stage {
        crate::gpu::Stage::Inject => "injecting".to_string(),
        crate::gpu::Stage::Propagate { lights } => {
            format!("propagating {lights} light{}", if lights == 1 { "" } else { "s" })
        }
        crate::gpu::Stage::Scatter => "solving multiple scattering".to_string(),
        crate::gpu::Stage::March => "marching at full resolution".to_string(),
        crate::gpu::Stage::Done => "converged".to_string(),
    };
    if p.stage == crate::gpu::Stage::Done {
        ui.label(format!("Preview: {stage}, {}×{} px", p.shown_size[0], p.shown_size[1]));
    } else {
        ui.label(format!(
            "Preview: {stage} ({:.0} %), showing {}×{} px",
            p.stage_fraction * 100.0,
            p.shown_size[0],
            p.shown_size[1]
        ))
        .on_hover_text("Each frame runs pipeline work within a frame budget; the preview refines over the next frames");
    }
    if p.shadows_stale {
        ui.colored_label(ui.visuals().warn_fg_color, "Shadows are stale while propagation catches up")
            .on_hover_text("The preview reads optical depths computed before the last edit");
    }
    ui.separator();
    let c = serde_json::to_value(r.counters).unwrap_or_default();
    egui::Grid::new("stats-counters").striped(true).num_columns(2).show(ui, |ui| {
        if let Some(map) = c.as_object() {
            for (k, v) in map {
                ui.label(k.replace('_', " "));
                ui.label(v.to_string());
                ui.end_row();
            }
        }
    });
    ui.separator();
    let p = state.session.project();
    ui.label(format!(
        "{} particles, {} lights, grid {:?}",
        p.particles.len(),
        p.lights.len(),
        p.grid.resolution.to_array()
    ));
    ui.label(format!(
        "Preview {}×{} px, {} frames rendered",
        state.view.preview_size[0], state.view.preview_size[1], gpu.renders
    ));
    ui.label(format!("Undo steps: {}", state.session.undo_len()));
}
