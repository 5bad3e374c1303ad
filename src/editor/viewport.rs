//! The Viewport tab: the tool bar, the pipeline's preview, camera navigation and the tools'
//! pointer handling: what a press starts, a drag continues and a release finishes. What is
//! drawn over the preview is `overlays`.

use super::commands::Command;
use super::gizmo;
use super::overlays::{self, shown_gizmo, AIM_HANDLE_RADIUS};
use super::state::{EditorState, Gesture};
use super::tools::{self, Hit, Stroke, Tool};
use super::view::{self, ViewProjection};
use crate::scene::FitKeep;
use egui::{Color32, Pos2, Rect, Sense, Ui};
use glam::Vec3;

pub(crate) fn show(state: &mut EditorState, ui: &mut Ui) {
    toolbar(state, ui);
    grid_warning(state, ui);
    let rect = ui.available_rect_before_wrap();
    if rect.width() < 8.0 || rect.height() < 8.0 {
        return;
    }
    let response = ui.allocate_rect(rect, Sense::click_and_drag());
    state.view.viewport_rect = Some(rect);
    let px = ui.ctx().pixels_per_point() * state.view.preview_scale.factor();
    let size =
        [((rect.width() * px).round() as u32).clamp(16, 4096), ((rect.height() * px).round() as u32).clamp(16, 4096)];
    state.view.preview_size = size;
    handle_input(state, ui, &response, rect);
    // Where a Paint stroke would start under the pointer, for the brush preview.
    state.view.brush_point = match response.hover_pos() {
        Some(pos) if state.view.tool == Tool::Paint && state.view.gesture.is_none() => {
            let vp = ViewProjection::new(&state.session.project().camera, rect);
            paint_point(state, &vp, pos)
        }
        _ => None,
    };

    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 0.0, Color32::from_gray(8));
    match &state.gpu {
        Some(gpu) => {
            if let Some((id, _)) = gpu.texture {
                painter.image(id, rect, Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)), Color32::WHITE);
            }
            if let Some(e) = &gpu.error {
                viewport_message(&painter, rect, e, ui.visuals().error_fg_color);
            }
        }
        None => {
            let msg = state.gpu_missing.clone().unwrap_or_default();
            viewport_message(&painter, rect, &msg, ui.visuals().error_fg_color);
        }
    }
    if let Some(text) = state.viewport_notice() {
        viewport_message(&painter, rect, text, ui.visuals().warn_fg_color);
    }
    overlays::overlays(state, &painter, rect, response.hover_pos());
    overlays::motion_paths(state, &painter, rect);
    overlays::gizmo_overlay(state, &painter, rect, response.hover_pos().or(ui.input(|i| i.pointer.latest_pos())));
}

/// A message over the lower part of the viewport, wrapped to its width on a dark backing, so
/// it is read whole and the last good image above it stays in view.
fn viewport_message(painter: &egui::Painter, rect: Rect, text: &str, colour: Color32) {
    let wrap = (rect.width() - 32.0).max(40.0);
    let galley = painter.layout(text.to_owned(), egui::FontId::proportional(14.0), colour, wrap);
    let at = Pos2::new(rect.center().x - galley.size().x * 0.5, rect.bottom() - galley.size().y - 20.0);
    let at = Pos2::new(at.x, at.y.max(rect.top() + 8.0));
    painter.rect_filled(Rect::from_min_size(at, galley.size()).expand(8.0), 4.0, Color32::from_black_alpha(215));
    painter.galley(at, galley, colour);
}

/// The row above the viewport that warns while particles reach outside the grid box, with
/// "Fit grid to particles". The row is always there (empty while nothing crosses), so the
/// warning's coming and going moves nothing under the pointer, and it covers no part of the
/// viewport.
fn grid_warning(state: &mut EditorState, ui: &mut Ui) {
    thread_local! {
        /// The count for one state of the project and its particles then: counting visits
        /// every particle, so a stroke's dabs are counted on their own.
        static CROSSING: std::cell::Cell<Option<(super::session::Version, usize, usize)>> = const { std::cell::Cell::new(None) };
    }
    let version = state.content_version();
    let project = state.session.project();
    let crossing = match CROSSING.get() {
        Some((v, n, _)) if v == version => n,
        cached => {
            let appended = cached.and_then(|(v, n, len)| {
                let grown = v.epoch == version.epoch && state.session.appended_since(v.generation) == Some(len);
                grown.then(|| n + project.particles_crossing_grid_from(len).len())
            });
            let n = appended.unwrap_or_else(|| project.particles_crossing_grid().len());
            CROSSING.set(Some((version, n, project.particles.len())));
            n
        }
    };
    let height = ui.spacing().interact_size.y;
    let size = egui::vec2(ui.available_width(), height);
    ui.allocate_ui_with_layout(size, egui::Layout::left_to_right(egui::Align::Center), |ui| {
        ui.set_min_size(size);
        if crossing > 0 {
            grid_warning_row(state, ui, crossing);
        }
    });
}

fn grid_warning_row(state: &mut EditorState, ui: &mut Ui, crossing: usize) {
    // The buttons first, so that a narrow viewport cuts the text short, not them.
    if ui
        .button("Fit grid to particles")
        .on_hover_text("Resize the grid box to hold every visible particle (one undo step)")
        .clicked()
    {
        fit_grid(state);
    }
    let keep = &mut state.view.fit_keep;
    ui.selectable_value(keep, FitKeep::CellSize, "keep cell size").on_hover_text("The resolution follows the new box");
    ui.selectable_value(keep, FitKeep::Resolution, "keep resolution")
        .on_hover_text("The cells stretch with the new box");
    let text = format!(
        "⚠ {crossing} particle{} reach{} outside the grid box: their fog is cut off at its faces",
        if crossing == 1 { "" } else { "s" },
        if crossing == 1 { "es" } else { "" }
    );
    let tip = format!(
        "A particle crosses the box when the ball where its extinction exceeds {} % of its peak (radius ≈ {:.2} r) is not inside the box",
        crate::scene::SUPPORT_FRACTION * 100.0,
        (1.0 / crate::scene::SUPPORT_FRACTION).ln().sqrt()
    );
    let label = egui::Label::new(egui::RichText::new(text).color(ui.visuals().warn_fg_color)).truncate();
    ui.add(label).on_hover_text(tip);
}

/// Resizes the grid box to the visible particles, as one undo step.
pub(crate) fn fit_grid(state: &mut EditorState) {
    let max_edge = state.gpu.as_ref().map_or(1024, |g| g.pipeline.context().max_grid_edge());
    match state.session.project().fit_grid_to_particles(state.view.fit_keep) {
        Ok(g) if g.resolution.max_element() > max_edge => state.error(format!(
            "Cannot fit the grid: it would need {:?} cells, more than this adapter's {max_edge} per axis; keep the resolution instead",
            g.resolution.to_array()
        )),
        Ok(g) => {
            state.session.edit_grid(crate::editor::session::NEW_STEP, |grid| *grid = g);
            let r = g.resolution;
            let left = state.session.project().particles_crossing_grid().len();
            let rest = match left {
                0 => String::new(),
                n => format!(
                    "; {n} particle{} still reach{} past a wall's or floor's edge where the box grew (Fit again to hold them too)",
                    if n == 1 { "" } else { "s" },
                    if n == 1 { "es" } else { "" }
                ),
            };
            state.info(format!(
                "Grid fitted to the particles: ({:.2}, {:.2}, {:.2}) to ({:.2}, {:.2}, {:.2}) m, {}×{}×{} cells{rest}",
                g.min.x, g.min.y, g.min.z, g.max.x, g.max.y, g.max.z, r.x, r.y, r.z
            ));
        }
        Err(e) => state.error(format!("Cannot fit the grid: {e}")),
    }
}

fn toolbar(state: &mut EditorState, ui: &mut Ui) {
    ui.horizontal_wrapped(|ui| {
        for tool in Tool::ALL {
            let text = format!("{} ({})", tool.label(), Command::for_tool(tool).shortcut_text());
            if ui.selectable_label(state.view.tool == tool, text).on_hover_text(tool.tooltip()).clicked() {
                state.view.tool = tool;
            }
        }
        ui.separator();
        // The Light tool's options take the brush's place, so the toolbar keeps its height.
        if state.view.tool == Tool::Light {
            ui.label("new light");
            for kind in crate::scene::LightKindChoice::ALL {
                ui.selectable_value(&mut state.view.new_light, kind, kind.label())
                    .on_hover_text("The kind of light a click on empty space adds (change it later in the Inspector)");
            }
            return;
        }
        let b = &mut state.view.brush;
        ui.add(egui::DragValue::new(&mut b.radius).speed(0.005).range(0.005..=10.0).prefix("radius ").suffix(" m"))
            .on_hover_text("Brush radius: the radius r of painted particles (σ = c·exp(−d²/r²)) and the brush footprint");
        ui.add(egui::DragValue::new(&mut b.density).speed(0.05).range(0.0..=1000.0).prefix("density ").suffix(" 1/m"))
            .on_hover_text("Peak extinction c of painted particles");
        ui.add(egui::DragValue::new(&mut b.spacing).speed(0.01).range(0.05..=4.0).prefix("spacing ").suffix("×r"))
            .on_hover_text("Distance between dabs along a stroke, in brush radii");
        ui.add(egui::DragValue::new(&mut b.jitter).speed(0.01).range(0.0..=2.0).prefix("jitter ").suffix("×r"))
            .on_hover_text("Random offset of each dab within the working plane, in brush radii");
        egui::ComboBox::from_id_salt("paint-depth")
            .selected_text(match b.depth {
                tools::PaintDepth::Fog => "at fog depth",
                tools::PaintDepth::Plane => "on working plane",
            })
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut b.depth, tools::PaintDepth::Fog, "at fog depth")
                    .on_hover_text("Paint where the fog under the cursor starts (optical depth 0.5 from the camera); the working plane where there is none");
                ui.selectable_value(&mut b.depth, tools::PaintDepth::Plane, "on working plane")
                    .on_hover_text("Paint on the plane through the grid centre, facing the camera");
            })
            .response
            .on_hover_text("Where Paint puts a stroke along the view ray");
    });
    ui.horizontal_wrapped(|ui| {
        use super::state::Quality;
        use crate::gpu::BakePhase;
        egui::ComboBox::new("quality", "preview")
            .selected_text(match state.view.quality {
                Quality::Balanced => "live",
                Quality::Full => "wait for full",
                Quality::AsBaked(BakePhase::Isotropic) => "as baked (isotropic)",
                Quality::AsBaked(BakePhase::Camera) => "as baked (camera)",
            })
            .show_ui(ui, |ui| {
                ui.selectable_value(&mut state.view.quality, Quality::Balanced, "live")
                    .on_hover_text("Each frame shows the edit at once (coarser, shadows may lag), then refines to full resolution over the next frames");
                ui.selectable_value(&mut state.view.quality, Quality::Full, "wait for full")
                    .on_hover_text("Every frame waits for the full-resolution image with fresh shadows (the window pauses; seconds per edit on software adapters)");
                ui.selectable_value(&mut state.view.quality, Quality::AsBaked(BakePhase::Isotropic), "as baked (isotropic)")
                    .on_hover_text("What an engine shows of the light bake with the isotropic phase: baked density and emission, no lights (for g ≠ 0 the view's phase is lost)");
                ui.selectable_value(&mut state.view.quality, Quality::AsBaked(BakePhase::Camera), "as baked (camera)")
                    .on_hover_text("What an engine shows of the light bake with the camera's phase: exact for this camera only");
            })
            .response
            .on_hover_text("How the preview trades responsiveness for finished frames");
        egui::ComboBox::new("preview-scale", "preview res")
            .width(52.0)
            .selected_text(state.view.preview_scale.label())
            .show_ui(ui, |ui| {
                for scale in super::state::PreviewScale::ALL {
                    ui.selectable_value(&mut state.view.preview_scale, scale, scale.label());
                }
            })
            .response
            .on_hover_text("Preview pixels per screen pixel: ½ and ¼ render 4× and 16× fewer pixels, for slow adapters and large windows");
        ui.separator();
        let mut exposure = state.session.project().render.exposure;
        let r = ui
            .add(egui::DragValue::new(&mut exposure).speed(0.02).range(0.0..=100.0).prefix("exposure "))
            .on_hover_text("Tone-mapping exposure: display = 1 − exp(−exposure · radiance)");
        if r.changed() {
            state.session.set_exposure(r.id.value(), exposure);
        }
    });
}

fn handle_input(state: &mut EditorState, ui: &Ui, response: &egui::Response, rect: Rect) {
    let camera = state.session.project().camera;
    let vp = ViewProjection::new(&camera, rect);
    let (modifiers, events, pointer) = ui.input(|i| (i.modifiers, i.raw.events.clone(), i.pointer.clone()));
    let hover = response.hover_pos();

    if state.view.modal.is_some() {
        modal(state, &vp, pointer.hover_pos(), ui, response);
        state.view.interacting = false;
        return;
    }

    let wheel = Wheel::from_events(&events);
    if let Some(pos) = hover {
        if state.view.tool == Tool::Scale {
            let now = ui.input(|i| i.time);
            if wheel.plain != 0.0 {
                wheel_scale(state, &vp, pos, wheel.plain, false, now);
            }
            if wheel.alt != 0.0 {
                wheel_scale(state, &vp, pos, wheel.alt, true, now);
            }
            if wheel.command != 0.0 {
                state.session.set_camera(view::zoom(&camera, (-wheel.command * 0.0015).exp()));
            }
        } else if wheel.total() != 0.0 {
            state.session.set_camera(view::zoom(&camera, (-wheel.total() * 0.0015).exp()));
        }
    }
    let zoom = ui.input(|i| i.zoom_delta());
    if hover.is_some() && zoom != 1.0 && !wheel.any {
        state.session.set_camera(view::zoom(&camera, 1.0 / zoom));
    }

    // A right click during a gizmo drag cancels it, as Escape does.
    let mut cancelled = false;
    if matches!(state.view.gesture, Some(Gesture::Gizmo { .. }))
        && events.iter().any(|e| {
            matches!(e, egui::Event::PointerButton { button: egui::PointerButton::Secondary, pressed: true, .. })
        })
    {
        state.cancel_gizmo();
        cancelled = true;
    }
    let nav = !cancelled
        && !matches!(state.view.gesture, Some(Gesture::Gizmo { .. } | Gesture::Cancelled))
        && (response.dragged_by(egui::PointerButton::Middle) || response.dragged_by(egui::PointerButton::Secondary));
    if nav {
        let delta = response.drag_delta();
        let c = if modifiers.shift {
            view::pan(&camera, delta, rect.height())
        } else {
            view::orbit(&camera, delta.x * 0.008, delta.y * 0.008)
        };
        state.session.set_camera(c);
        state.view.gesture = Some(if modifiers.shift { Gesture::Pan } else { Gesture::Orbit });
    }

    let primary_pressed = response.drag_started_by(egui::PointerButton::Primary)
        || (response.clicked_by(egui::PointerButton::Primary) && state.view.gesture.is_none());
    let pos = pointer.interact_pos().or(hover);

    let mut down_at_start = true;
    if primary_pressed {
        // The gesture starts where the button went down: egui reports a drag only once the
        // pointer has moved a few points away from there.
        if let Some(origin) = pointer.press_origin().or(pos) {
            start_gesture(state, &vp, origin, modifiers);
        }
        down_at_start = !events.iter().any(|e| is_primary(e, true));
    }
    let track = PrimaryTrack::from_events(&events, down_at_start);
    if pointer.primary_down() || track.released.is_some() {
        let points = if track.points.is_empty() {
            pos.filter(|_| primary_pressed).into_iter().collect()
        } else {
            track.points.clone()
        };
        continue_gesture(state, &vp, &points, modifiers);
    }
    if track.released.is_some()
        || response.drag_stopped()
        || response.clicked()
        || (!pointer.any_down() && state.view.gesture.is_some())
    {
        finish_gesture(state, &vp, track.released.or(pos), modifiers);
    }
    state.view.interacting = state.view.force_interacting
        || matches!(
            state.view.gesture,
            Some(
                Gesture::Orbit
                    | Gesture::Pan
                    | Gesture::Move { .. }
                    | Gesture::MoveLight { .. }
                    | Gesture::AimSpot { .. }
                    | Gesture::Gizmo { .. }
            )
        );
}

fn is_primary(e: &egui::Event, pressed: bool) -> bool {
    matches!(e, egui::Event::PointerButton { button: egui::PointerButton::Primary, pressed: p, .. } if *p == pressed)
}

/// Where the pointer went this frame while the primary button was held, in event order,
/// up to and including the release. Strokes follow these rather than the pointer's final
/// position, which may lie well past the release when the mouse keeps moving.
#[derive(Clone, Debug, Default)]
struct PrimaryTrack {
    points: Vec<Pos2>,
    released: Option<Pos2>,
}

impl PrimaryTrack {
    fn from_events(events: &[egui::Event], down_at_start: bool) -> Self {
        let mut track = Self::default();
        let mut down = down_at_start;
        for e in events {
            match e {
                egui::Event::PointerButton { pos, button: egui::PointerButton::Primary, pressed, .. } => {
                    if *pressed {
                        down = true;
                        track.points.push(*pos);
                    } else if down {
                        track.points.push(*pos);
                        track.released = Some(*pos);
                        break;
                    }
                }
                egui::Event::PointerMoved(p) if down => track.points.push(*p),
                _ => {}
            }
        }
        track
    }
}

/// This frame's wheel movement in points (lines count as 40), split by the modifiers held
/// at each event: a quick Alt+wheel may start and end within one frame.
#[derive(Clone, Copy, Debug, Default)]
struct Wheel {
    plain: f32,
    alt: f32,
    command: f32,
    any: bool,
}

impl Wheel {
    fn from_events(events: &[egui::Event]) -> Self {
        let mut w = Self::default();
        for e in events {
            if let egui::Event::MouseWheel { unit, delta, modifiers, .. } = e {
                let d = match unit {
                    egui::MouseWheelUnit::Point => delta.y,
                    egui::MouseWheelUnit::Line => delta.y * 40.0,
                    egui::MouseWheelUnit::Page => delta.y * 400.0,
                };
                w.any = true;
                if modifiers.command {
                    w.command += d;
                } else if modifiers.alt {
                    w.alt += d;
                } else {
                    w.plain += d;
                }
            }
        }
        w
    }
    fn total(&self) -> f32 {
        self.plain + self.alt + self.command
    }
}

fn wheel_scale(state: &mut EditorState, vp: &ViewProjection, pos: Pos2, scroll: f32, density: bool, now: f64) {
    let targets = if state.session.selection.particles.is_empty() {
        view::under_brush(state.session.project(), vp, pos, state.view.brush.radius)
    } else {
        state.session.selection.particles.clone()
    };
    if targets.is_empty() {
        return;
    }
    let tag = match state.view.scale_wheel {
        Some((tag, last)) if now - last < 0.6 => tag,
        _ => {
            state.session.end_edit();
            state.session.new_tag()
        }
    };
    state.view.scale_wheel = Some((tag, now));
    state.session.scale_particles(tag, &targets, (scroll * 0.002).exp(), density);
}

/// The selected spot whose aim handle is under `pos` (Select and Light tools), with its tip
/// and the tip's depth.
fn aim_handle_at(state: &EditorState, vp: &ViewProjection, pos: Pos2) -> Option<(usize, Vec3, f32)> {
    if !matches!(state.view.tool, Tool::Select | Tool::Light) {
        return None;
    }
    let project = state.session.project();
    state.session.selection.lights.iter().find_map(|&i| {
        let tip = project.spot_tip(project.lights.get(i)?)?;
        let (at, depth) = vp.project(tip)?;
        (at.distance(pos) <= AIM_HANDLE_RADIUS + 3.0).then_some((i, tip, depth))
    })
}

fn start_gesture(state: &mut EditorState, vp: &ViewProjection, pos: Pos2, modifiers: egui::Modifiers) {
    if let Some((light, tip, depth)) = aim_handle_at(state, vp, pos) {
        let tag = state.session.new_tag();
        state.view.gesture = Some(Gesture::AimSpot { tag, light, depth, start: pos, tip });
        return;
    }
    // A press on a handle of the move gizmo drags the selection along its axis or plane.
    if let Some(g) = shown_gizmo(state, vp) {
        if let Some((handle, grab)) = g.handle_at(pos).and_then(|h| Some((h, gizmo::drag_point(h, g.center, vp, pos)?)))
        {
            let tag = state.session.new_tag();
            state.view.gesture =
                Some(Gesture::Gizmo { tag, handle, center: g.center, grab, applied: Vec3::ZERO, snap: false });
            return;
        }
    }
    // Only a selection uses the particle picked; other tools keep the scan.
    let index = if state.view.tool == Tool::Select { state.particle_index() } else { None };
    let project = state.session.project();
    state.view.gesture = match state.view.tool {
        Tool::Select => match view::pick_with(project, index.as_deref(), vp, pos) {
            Some(hit) => {
                let selected = match hit {
                    Hit::Particle(i) => state.session.selection.particles.contains(&i),
                    Hit::Light(i) => state.session.selection.lights.contains(&i),
                };
                if modifiers.shift || modifiers.command {
                    toggle(state, hit, true);
                    None
                } else {
                    if !selected {
                        state.session.selection.clear();
                        toggle(state, hit, false);
                    }
                    let depth = state.session.selection_center().and_then(|c| vp.project(c)).map_or(1.0, |(_, z)| z);
                    Some(Gesture::Move { tag: state.session.new_tag(), depth, start: pos, applied: Vec3::ZERO })
                }
            }
            None => Some(Gesture::Box { start: pos }),
        },
        Tool::Paint => {
            let mut stroke = Stroke::new(state.session.new_tag());
            stroke.anchor = paint_point(state, vp, pos);
            let grid = state.session.project().grid;
            let inside = stroke.anchor.and_then(|p| tools::into_grid_along_ray(&grid, vp.position, vp.ray(pos), p));
            stroke.outside = inside.is_none();
            if let Some(point) = inside {
                let dabs = inside_grid(&grid, stroke.dabs_to(point, vp.right, vp.up, &state.view.brush));
                state.session.add_particles(stroke.tag, dabs);
            }
            Some(Gesture::Paint(stroke))
        }
        Tool::Erase => {
            let tag = state.session.new_tag();
            state.session.erase_along_ray(tag, vp.position, vp.ray(pos), state.view.brush.radius);
            Some(Gesture::Erase { tag })
        }
        Tool::Scale => {
            let targets = if state.session.selection.particles.is_empty() {
                view::under_brush(project, vp, pos, state.view.brush.radius)
            } else {
                state.session.selection.particles.clone()
            };
            Some(Gesture::ScaleDrag { tag: state.session.new_tag(), targets, last_x: pos.x })
        }
        Tool::Light => {
            // Press on a light: drag it. Press on empty space: add a light there (a drag
            // then places it).
            let hit = view::pick(project, vp, pos);
            let point = tools::working_plane_point(project, vp, pos);
            let tag = state.session.new_tag();
            let light = match hit {
                Some(Hit::Light(i)) => Some(i),
                _ => point.map(|point| {
                    let i = state.session.add_light_tagged(tag, crate::scene::Light::new(point, 2.0, Vec3::ONE));
                    // Another kind is made from the point light as the Inspector would make it.
                    let kind = state.view.new_light;
                    state.session.set_light_kind(tag, i, kind);
                    i
                }),
            };
            light.map(|i| {
                let depth = {
                    let p = state.session.project();
                    p.lights.get(i).and_then(|l| vp.project(p.light_anchor(l))).map_or(1.0, |(_, z)| z)
                };
                state.session.selection.clear();
                state.session.selection.lights.insert(i);
                Gesture::MoveLight { tag, light: i, depth, start: pos, applied: Vec3::ZERO }
            })
        }
    };
}

fn toggle(state: &mut EditorState, hit: Hit, toggle: bool) {
    let set = match hit {
        Hit::Particle(i) => (&mut state.session.selection.particles, i),
        Hit::Light(i) => (&mut state.session.selection.lights, i),
    };
    if toggle && set.0.contains(&set.1) {
        set.0.remove(&set.1);
    } else {
        set.0.insert(set.1);
    }
}

/// Continues the gesture through `points`, where the pointer went this frame while the
/// button was held.
/// Where a Paint stroke starting at `pos` paints: at the fog's depth under the cursor (from
/// the pipeline's EV as it stands), else on the working plane.
fn paint_point(state: &mut EditorState, vp: &ViewProjection, pos: Pos2) -> Option<Vec3> {
    if state.view.brush.depth == tools::PaintDepth::Fog {
        if let Some(p) =
            state.fog_ev().and_then(|ev| tools::fog_depth_point(ev, vp.position, vp.ray(pos), tools::FOG_DEPTH_TAU))
        {
            return Some(p);
        }
    }
    tools::working_plane_point(state.session.project(), vp, pos)
}

/// `dabs` with their centres kept inside the grid box (a jittered dab may fall just outside).
fn inside_grid(grid: &crate::scene::GridSpec, mut dabs: Vec<crate::scene::Particle>) -> Vec<crate::scene::Particle> {
    for d in &mut dabs {
        d.center = d.center.clamp(grid.min, grid.max);
    }
    dabs
}

fn continue_gesture(state: &mut EditorState, vp: &ViewProjection, points: &[Pos2], modifiers: egui::Modifiers) {
    let alt = modifiers.alt;
    let brush = state.view.brush;
    let cell = state.session.project().grid.cell_size();
    let Some(&last) = points.last() else { return };
    match &mut state.view.gesture {
        Some(Gesture::Paint(stroke)) => {
            let grid = state.session.project().grid;
            let mut dabs = Vec::new();
            for &p in points {
                let on_plane = stroke.anchor.and_then(|a| vp.on_view_plane(p, a));
                let inside =
                    on_plane.and_then(|point| tools::into_grid_along_ray(&grid, vp.position, vp.ray(p), point));
                stroke.outside = on_plane.is_some() && inside.is_none();
                if let Some(point) = inside {
                    dabs.extend(inside_grid(&grid, stroke.dabs_to(point, vp.right, vp.up, &brush)));
                }
            }
            if !dabs.is_empty() {
                let tag = stroke.tag;
                state.session.add_particles(tag, dabs);
            }
        }
        Some(Gesture::Erase { tag }) => {
            let tag = *tag;
            for &p in points {
                state.session.erase_along_ray(tag, vp.position, vp.ray(p), brush.radius);
            }
        }
        Some(Gesture::Move { tag, depth, start, applied }) => {
            let total = vp.drag_to_world(last - *start, *depth);
            let step = total - *applied;
            *applied = total;
            let tag = *tag;
            if step != Vec3::ZERO {
                state.session.translate_selection(tag, step);
            }
        }
        Some(Gesture::MoveLight { tag, light, depth, start, applied }) => {
            let total = vp.drag_to_world(last - *start, *depth);
            let step = total - *applied;
            *applied = total;
            let (tag, light) = (*tag, *light);
            if step != Vec3::ZERO {
                state.session.move_light(tag, light, step);
            }
        }
        Some(Gesture::AimSpot { tag, light, depth, start, tip }) => {
            let target = *tip + vp.drag_to_world(last - *start, *depth);
            let (tag, light) = (*tag, *light);
            if state.session.project().lights.get(light).is_some_and(|l| l.position != target) {
                state.session.aim_spot(tag, light, target);
            }
        }
        Some(Gesture::Gizmo { tag, handle, center, grab, applied, snap }) => {
            // The pointer's last position decides (not the path it took): a point the handle
            // cannot reach (its axis along the view ray) leaves the selection where it is.
            let Some(point) = gizmo::drag_point(*handle, *center, vp, last) else { return };
            *snap = modifiers.ctrl || modifiers.command;
            let grid_min = state.session.project().grid.min;
            let snap_to = gizmo::Snap { center: *center, grid_min, cell };
            let total = gizmo::displacement(*handle, *grab, point, snap.then_some(snap_to));
            let step = total - *applied;
            *applied = total;
            let tag = *tag;
            if step != Vec3::ZERO {
                state.session.translate_selection(tag, step);
            }
        }
        Some(Gesture::ScaleDrag { tag, targets, last_x }) => {
            let dx = last.x - *last_x;
            *last_x = last.x;
            if dx != 0.0 {
                let (tag, targets) = (*tag, targets.clone());
                state.session.scale_particles(tag, &targets, (dx * 0.01).exp(), alt);
            }
        }
        _ => {}
    }
}

fn finish_gesture(state: &mut EditorState, vp: &ViewProjection, pos: Option<Pos2>, modifiers: egui::Modifiers) {
    if let (Some(Gesture::Box { start }), Some(end)) = (&state.view.gesture, pos) {
        let r = Rect::from_two_pos(*start, end);
        if r.area() > 4.0 {
            let index = state.particle_index();
            let (particles, lights) = view::box_select_with(state.session.project(), index.as_deref(), vp, r);
            if !(modifiers.shift || modifiers.command) {
                state.session.selection.clear();
            }
            state.session.selection.particles.extend(particles);
            state.session.selection.lights.extend(lights);
        } else if !(modifiers.shift || modifiers.command) {
            state.session.selection.clear();
        }
    }
    state.view.gesture = None;
    state.session.end_edit();
}

fn modal(state: &mut EditorState, vp: &ViewProjection, pos: Option<Pos2>, ui: &Ui, response: &egui::Response) {
    let Some(pos) = pos else { return };
    let confirm = response.clicked() || ui.input(|i| i.key_pressed(egui::Key::Enter));
    let cancel = response.secondary_clicked();
    let Some(center) = state.session.selection_center() else {
        state.view.modal = None;
        return;
    };
    let Some((center_screen, depth)) = vp.project(center) else { return };
    let Some(m) = &mut state.view.modal else { return };
    if m.scale {
        let d0 = m.start.distance(center_screen).max(4.0);
        let factor = (pos.distance(center_screen) / d0).clamp(0.01, 100.0);
        let step = factor / m.applied_factor;
        m.applied_factor = factor;
        let (tag, targets) = (m.tag, state.session.selection.particles.clone());
        state.session.scale_particles(tag, &targets, step, ui.input(|i| i.modifiers.alt));
    } else {
        let total = vp.drag_to_world(pos - m.start, depth);
        let step = total - m.applied;
        m.applied = total;
        let tag = m.tag;
        state.session.translate_selection(tag, step);
    }
    if cancel {
        state.cancel_modal();
    } else if confirm {
        state.view.modal = None;
        state.session.end_edit();
    }
}
