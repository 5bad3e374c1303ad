//! The Slices tab: one slice of the baked volumes (extinction, optical depth, transmittance
//! or the error against the exact optical depth), read back when the project or the
//! settings change, painted on with the Paint tool.

use super::slices::{self, Axis, Colormap, Field, Scale};
use super::state::{EditorState, ExactKey, Gesture, SliceKey};
use super::tools::{Stroke, Tool};
use crate::gpu::SliceSource;
use egui::{Color32, Pos2, Rect, Sense, Ui};
use glam::Vec3;

pub(crate) fn show(state: &mut EditorState, ui: &mut Ui) {
    let lights = state.session.project().lights.len();
    let grid = state.session.project().grid;
    let s = &mut state.view.slices;
    ui.horizontal_wrapped(|ui| {
        egui::ComboBox::from_id_salt("slice-field").selected_text(s.field.label()).show_ui(ui, |ui| {
            for f in Field::ALL {
                ui.selectable_value(&mut s.field, f, f.label());
            }
        })
        .response
        .on_hover_text("EV: extinction σt; OPV: optical depth τ towards a light; exp(−τ): transmittance; error: |τ − τ_exact| against the CPU reference on this slice");
        if s.field.needs_light() {
            let project = state.session.project();
            let name = |i: usize| project.light_label(i);
            egui::ComboBox::from_id_salt("slice-light").selected_text(name(s.light)).show_ui(ui, |ui| {
                for i in 0..lights {
                    ui.selectable_value(&mut s.light, i, name(i));
                }
            });
        }
        for axis in Axis::ALL {
            ui.selectable_value(&mut s.axis, axis, axis.label()).on_hover_text(format!("Slice across the {} axis", axis.label()));
        }
        let max = grid.resolution.to_array()[s.axis.index()].saturating_sub(1);
        s.index = s.index.min(max);
        ui.add(egui::Slider::new(&mut s.index, 0..=max).text("cell")).on_hover_text("Slice index along the axis");
        egui::ComboBox::from_id_salt("slice-cmap").selected_text(s.colormap.label()).show_ui(ui, |ui| {
            for c in Colormap::ALL {
                ui.selectable_value(&mut s.colormap, c, c.label());
            }
        });
        ui.checkbox(&mut s.log, "log").on_hover_text("Logarithmic colour scale over six decades below the maximum");
    });
    if state.view.slices.field.needs_light() && lights == 0 {
        ui.label("The project has no lights: add one with the Light tool.");
        return;
    }
    state.view.slices.light = state.view.slices.light.min(lights.saturating_sub(1));
    refresh_slice(state, ui.ctx());

    if let Some(e) = &state.view.slice.error {
        ui.colored_label(ui.visuals().error_fg_color, e);
    }
    let (Some(slice), Some(tex)) = (state.view.slice.slice.clone(), state.view.slice.texture.clone()) else {
        if state.view.slice.exact_pending.is_some() {
            ui.horizontal(|ui| {
                ui.spinner();
                ui.label("Computing the exact optical depth on this slice…");
            });
        }
        return;
    };
    let (lo, hi) = slice.range();
    let scale = Scale::for_range(lo, hi, state.view.slices.log);
    let avail = ui.available_rect_before_wrap();
    let bar_w = 70.0;
    let probe_h = 20.0;
    let img_area = Rect::from_min_max(avail.min, Pos2::new(avail.max.x - bar_w, avail.max.y - probe_h));
    let (ua, va) = slice.axis.image_axes();
    let world = grid.size().to_array();
    let aspect = world[ua] / world[va];
    let mut w = img_area.width();
    let mut h = w / aspect;
    if h > img_area.height() {
        h = img_area.height();
        w = h * aspect;
    }
    if w < 4.0 || h < 4.0 {
        return;
    }
    let img_rect = Rect::from_min_size(img_area.min, egui::vec2(w, h));
    let response = ui.allocate_rect(Rect::from_min_max(avail.min, avail.max), Sense::click_and_drag());
    let painter = ui.painter_at(avail);
    painter.image(tex.id(), img_rect, Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)), Color32::WHITE);
    colour_bar(
        &painter,
        Rect::from_min_size(
            Pos2::new(img_rect.max.x + 8.0, img_rect.min.y + 7.0),
            egui::vec2(14.0, (h - 14.0).max(4.0)),
        ),
        state.view.slices.colormap,
        &scale,
        ui,
    );

    let hover = response.hover_pos().filter(|p| img_rect.contains(*p));
    let unit = state.view.slices.field.unit();
    state.view.slice.hover = hover.map(|p| {
        let x = (((p.x - img_rect.min.x) / w * slice.width as f32) as usize).min(slice.width - 1);
        let y = (((p.y - img_rect.min.y) / h * slice.height as f32) as usize).min(slice.height - 1);
        let [i, j, k] = slice.cell(x, y);
        let c = grid.cell_center(i, j, k);
        format!(
            "cell ({i}, {j}, {k}) · world ({:.3}, {:.3}, {:.3}) m · value {:.5} {unit}",
            c.x,
            c.y,
            c.z,
            slice.get(x, y)
        )
    });
    // World axes and units on the image, in the plane's axis colour.
    let [across, up, plane] = super::slices::slice_axis_labels(&grid, slice.axis, slice.index);
    // Readable over any heatmap: 13 px, the axis colour lightened, on a near-opaque backing.
    let small = |t: String, c: Color32| {
        let light = c.lerp_to_gamma(Color32::WHITE, 0.45);
        egui::Label::new(
            egui::RichText::new(t).size(13.0).color(light).background_color(Color32::from_black_alpha(215)),
        )
    };
    let (ua, va) = slice.axis.image_axes();
    let colour = |a: usize| [Axis::X, Axis::Y, Axis::Z][a].colour();
    let mut corner_label = |at: Pos2, label: egui::Label| {
        let r = Rect::from_min_size(at, egui::vec2(w, 19.0));
        ui.scope_builder(
            egui::UiBuilder::new().max_rect(r).layout(egui::Layout::left_to_right(egui::Align::Min)),
            |ui| ui.add(label),
        );
    };
    corner_label(img_rect.left_bottom() - egui::vec2(-2.0, 20.0), small(across, colour(ua)));
    corner_label(img_rect.left_top() + egui::vec2(2.0, 2.0), small(up, colour(va)));
    corner_label(img_rect.left_top() + egui::vec2(2.0, 22.0), small(plane, slice.axis.colour()));
    let probe = state.view.slice.hover.clone().unwrap_or_else(|| format!("range {lo:.4} … {hi:.4} {unit}"));
    painter.text(
        Pos2::new(avail.min.x, img_rect.max.y + 4.0),
        egui::Align2::LEFT_TOP,
        probe,
        egui::FontId::monospace(12.0),
        ui.visuals().text_color(),
    );

    if state.view.tool == Tool::Paint {
        slice_paint(state, &response, img_rect, slice.axis, slice.index);
    }
}

fn slice_paint(state: &mut EditorState, response: &egui::Response, img_rect: Rect, axis: Axis, index: u32) {
    let grid = state.session.project().grid;
    let (ua, va) = axis.image_axes();
    let to_world = |p: Pos2| {
        let u = ((p.x - img_rect.min.x) / img_rect.width()).clamp(0.0, 1.0);
        let v = 1.0 - ((p.y - img_rect.min.y) / img_rect.height()).clamp(0.0, 1.0);
        let mut w = grid
            .cell_center(
                index.min(grid.resolution.x - 1),
                index.min(grid.resolution.y - 1),
                index.min(grid.resolution.z - 1),
            )
            .to_array();
        let (min, size) = (grid.min.to_array(), grid.size().to_array());
        w[ua] = min[ua] + u * size[ua];
        w[va] = min[va] + v * size[va];
        Vec3::from_array(w)
    };
    let mut right = [0.0f32; 3];
    let mut up = [0.0f32; 3];
    right[ua] = 1.0;
    up[va] = 1.0;
    if response.drag_started_by(egui::PointerButton::Primary) || response.clicked() {
        state.view.gesture = Some(Gesture::SlicePaint(Stroke::new(state.session.new_tag())));
    }
    if let (Some(Gesture::SlicePaint(stroke)), Some(p)) = (&mut state.view.gesture, response.interact_pointer_pos()) {
        if img_rect.contains(p) {
            let dabs = stroke.dabs_to(to_world(p), Vec3::from_array(right), Vec3::from_array(up), &state.view.brush);
            let tag = stroke.tag;
            if !dabs.is_empty() {
                state.session.add_particles(tag, dabs);
            }
        }
    }
    if response.drag_stopped() || response.clicked() {
        state.view.gesture = None;
        state.session.end_edit();
    }
}

fn colour_bar(painter: &egui::Painter, rect: Rect, cmap: Colormap, scale: &Scale, ui: &Ui) {
    let n = 48;
    for i in 0..n {
        let t0 = i as f32 / n as f32;
        let y0 = rect.max.y - t0 * rect.height();
        let y1 = rect.max.y - (i + 1) as f32 / n as f32 * rect.height();
        painter.rect_filled(Rect::from_x_y_ranges(rect.x_range(), y1..=y0), 0.0, cmap.color(t0 + 0.5 / n as f32));
    }
    painter.rect_stroke(rect, 0.0, egui::Stroke::new(1.0, ui.visuals().weak_text_color()), egui::StrokeKind::Outside);
    for k in 0..=4 {
        let t = k as f32 / 4.0;
        let y = rect.max.y - t * rect.height();
        let v = scale.value_at(t);
        let text = if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e4) { format!("{v:.1e}") } else { format!("{v:.3}") };
        painter.line_segment(
            [Pos2::new(rect.max.x, y), Pos2::new(rect.max.x + 4.0, y)],
            egui::Stroke::new(1.0, ui.visuals().text_color()),
        );
        painter.text(
            Pos2::new(rect.max.x + 6.0, y),
            egui::Align2::LEFT_CENTER,
            text,
            egui::FontId::monospace(12.0),
            ui.visuals().strong_text_color(),
        );
    }
}

/// Reads back and colours the slice if the project or the settings changed.
fn refresh_slice(state: &mut EditorState, ctx: &egui::Context) {
    let settings = state.view.slices;
    // The volumes change when the pipeline finishes baking them, frames after the edit.
    let baked = state.gpu.as_ref().map_or(0, |g| g.pipeline.volumes_generation());
    let key = SliceKey { epoch: state.epoch, volumes: baked, settings };
    if state.view.slice.key == Some(key) {
        return;
    }
    let Some(gpu) = &state.gpu else {
        state.view.slice.error = state.gpu_missing.clone();
        return;
    };
    if let Some(e) = &gpu.error {
        state.view.slice.error = Some(e.clone());
        state.view.slice.key = Some(key);
        return;
    }
    let source = match settings.field {
        Field::Extinction => SliceSource::Extinction,
        _ => SliceSource::OpticalDepth { light: settings.light },
    };
    let grid = state.session.project().grid;
    let index = slices::clamp_index(&grid, settings.axis, settings.index);
    let Some(gpu) = &mut state.gpu else { return };
    let plane = match gpu.pipeline.read_slice(source, settings.axis.index(), index) {
        Ok(p) => p,
        Err(e) => {
            state.view.slice.error = Some(e.to_string());
            state.view.slice.key = Some(key);
            return;
        }
    };
    let mut slice = slices::from_plane(&plane, settings.axis);
    state.view.slice.error = None;
    match settings.field {
        Field::Transmittance => slice.values.iter_mut().for_each(|v| *v = (-*v).exp()),
        Field::Error | Field::ResolutionError => {
            let ek = ExactKey {
                version: state.content_version(),
                light: settings.light,
                axis: settings.axis,
                index: slice.index,
            };
            match &state.view.slice.exact {
                Some((k, Ok(exact))) if *k == ek => slice = slices::error_slice(&slice, exact, settings.field),
                Some((k, Err(e))) if *k == ek => {
                    state.view.slice.error = Some(format!("Error view unavailable: {e}"));
                    state.view.slice.slice = None;
                    state.view.slice.key = Some(key);
                    return;
                }
                _ => {
                    let cells = slice.cells();
                    state.request_exact(ek, cells);
                    state.view.slice.slice = None;
                    state.view.slice.texture = None;
                    return;
                }
            }
        }
        Field::Extinction | Field::OpticalDepth => {}
    }
    let (lo, hi) = slice.range();
    let image = slices::colorize(&slice, settings.colormap, &Scale::for_range(lo, hi, settings.log));
    let options = egui::TextureOptions::NEAREST;
    match &mut state.view.slice.texture {
        Some(t) => t.set(image, options),
        None => state.view.slice.texture = Some(ctx.load_texture("slice", image, options)),
    }
    state.view.slice.slice = Some(slice);
    state.view.slice.key = Some(key);
}
