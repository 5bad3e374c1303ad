//! The viewport's overlays, drawn over the preview: the grid box, particle outlines, light
//! gizmos and their aims, the selection, the move gizmo and the motion paths of selected
//! animated particles and lights. They read the editor's state and change nothing.

use super::gizmo::{self, Gizmo, Handle};
use super::state::{EditorState, Gesture};
use super::timeline::MOTION_PATH;
use super::tools::{self, Tool};
use super::view::ViewProjection;
use egui::{Color32, Pos2, Rect, Stroke as Line};
use glam::Vec3;

const SELECTED: Color32 = Color32::from_rgb(255, 160, 40);
/// Most frames sampled along a motion path.
const MAX_PATH_POINTS: i32 = 2000;
/// Particles drawn with outlines; beyond this only the selection is outlined.
const MAX_OUTLINES: usize = 20_000;
/// Furthest a faint outline's polygon strays from its circle, in points.
const OUTLINE_TOLERANCE: f32 = 0.5;

/// A circle's outline as a polygon within [`OUTLINE_TOLERANCE`] of it. egui strokes circles
/// with 64 or 128 sides at the sizes particles have on screen; hundreds of them overlapping
/// cost a software rasteriser more than the rest of the window, for lines no one can tell from
/// these.
fn faint_circle(centre: Pos2, radius: f32, stroke: Line) -> egui::Shape {
    let half_angle = (1.0 - OUTLINE_TOLERANCE / radius.max(OUTLINE_TOLERANCE)).acos();
    let sides = (std::f32::consts::PI / half_angle.max(1e-3)).ceil().clamp(8.0, 128.0) as usize;
    let points = (0..sides)
        .map(|k| {
            let a = std::f32::consts::TAU * k as f32 / sides as f32;
            centre + radius * egui::vec2(a.cos(), a.sin())
        })
        .collect();
    egui::Shape::closed_line(points, stroke)
}

/// The move gizmo, where it is shown: Select tool, a selection, no G / S under way.
pub(super) fn shown_gizmo(state: &EditorState, vp: &ViewProjection) -> Option<Gizmo> {
    if !state.view.show_gizmo || state.view.tool != Tool::Select || state.view.modal.is_some() {
        return None;
    }
    Gizmo::new(state.session.selection_center()?, vp)
}

/// Radius in points of a selected spot's aim handle, drawn and picked.
pub(super) const AIM_HANDLE_RADIUS: f32 = 5.0;

/// A sun's direction as an arrow from its anchor outside the grid towards the grid, and a
/// spot's axis as a line with its cone's edges, so both read as aimed lights.
fn light_direction(
    project: &crate::scene::Project,
    vp: &ViewProjection,
    painter: &egui::Painter,
    l: &crate::scene::Light,
    anchor: Vec3,
    colour: Color32,
    selected: bool,
) {
    use crate::scene::LightKind;
    let width = if selected { 2.5 } else { 1.5 };
    let colour = if selected { SELECTED } else { colour };
    let (direction, length, cone) = match l.kind {
        LightKind::Directional { direction } => (direction, project.sun_distance() * 0.45, None),
        LightKind::Spot { direction, angle_deg, .. } => {
            (direction, project.sun_distance() * 0.25, Some(angle_deg.to_radians()))
        }
        LightKind::Point => return,
    };
    let d = direction.normalize_or(Vec3::NEG_Y);
    let tip = anchor + d * length;
    let (Some((a, _)), Some((b, _))) = (vp.project(anchor), vp.project(tip)) else { return };
    painter.line_segment([a, b], Line::new(width, colour));
    let along = (b - a).normalized();
    if cone.is_none() && along.length() > 0.5 {
        let side = along.rot90();
        painter.add(egui::Shape::convex_polygon(
            vec![b + along * 4.0, b - along * 10.0 + side * 6.0, b - along * 10.0 - side * 6.0],
            colour,
            Line::NONE,
        ));
    }
    if cone.is_some() && selected {
        // The aim handle: drag it to point the spot.
        painter.circle(b, AIM_HANDLE_RADIUS, colour, egui::Stroke::new(1.0, Color32::BLACK));
    }
    if let Some(angle) = cone {
        // Two edges of the cone, in a plane through the axis.
        let side = d.any_orthonormal_vector();
        for s in [-1.0f32, 1.0] {
            let edge = (d * angle.cos() + side * s * angle.sin()) * length;
            if let Some((e, _)) = vp.project(anchor + edge) {
                painter.line_segment([a, e], Line::new(1.0, colour.gamma_multiply(0.6)));
            }
        }
    }
}

/// The path over the frame range of each selected particle's animated centre and light's
/// animated position, with a dot at each key.
pub(super) fn motion_paths(state: &EditorState, painter: &egui::Painter, rect: Rect) {
    use crate::scene::animation::{Channel, KeyValue, Object, Prop};
    let project = state.session.project();
    let Some(a) = project.animation else { return };
    let vp = ViewProjection::new(&project.camera, rect);
    let step = ((a.end - a.start) / MAX_PATH_POINTS).max(1) as usize;
    for object in state.session.selected_objects() {
        let prop = match object {
            Object::Particle(_) => Prop::Center,
            _ => Prop::Position,
        };
        let Some(track) = project.track(Channel(object, prop)) else { continue };
        let at = |v: Option<KeyValue>| match v {
            Some(KeyValue::Vec3(v)) => vp.project(v).map(|(p, _)| p),
            _ => None,
        };
        let points: Vec<Pos2> = (a.start..=a.end).step_by(step).filter_map(|f| at(track.sample(f))).collect();
        painter.add(egui::Shape::line(points, Line::new(1.5, MOTION_PATH)));
        for k in &track.keys {
            if let Some(p) = at(Some(k.value)) {
                painter.circle(p, 3.5, MOTION_PATH, Line::new(1.0, Color32::BLACK));
            }
        }
    }
}

pub(super) fn overlays(state: &EditorState, painter: &egui::Painter, rect: Rect, hover: Option<Pos2>) {
    let project = state.session.project();
    let vp = ViewProjection::new(&project.camera, rect);
    if state.view.show_slice_plane {
        // The Slices panel's plane as a translucent quad in its axis colour.
        let s = &state.view.slices;
        let corners = super::slices::slice_plane_corners(&project.grid, s.axis, s.index);
        let points: Option<Vec<Pos2>> = corners.iter().map(|&c| vp.project(c).map(|(p, _)| p)).collect();
        if let Some(points) = points {
            let c = s.axis.colour();
            let fill = Color32::from_rgba_unmultiplied(c.r(), c.g(), c.b(), 56);
            painter.add(egui::Shape::convex_polygon(points, fill, Line::new(1.5, c)));
        }
    }
    let g = &project.grid;
    let corners: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { g.min.x } else { g.max.x },
                if i & 2 == 0 { g.min.y } else { g.max.y },
                if i & 4 == 0 { g.min.z } else { g.max.z },
            )
        })
        .collect();
    let grid_line = Line::new(1.0, Color32::from_rgba_unmultiplied(160, 170, 190, 110));
    for (a, b) in [(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)] {
        if let (Some((pa, _)), Some((pb, _))) = (vp.project(corners[a]), vp.project(corners[b])) {
            painter.line_segment([pa, pb], grid_line);
        }
    }
    let outline = Line::new(1.0, Color32::from_rgba_unmultiplied(200, 220, 255, 45));
    let draw_all = state.view.outline_all && project.particles.len() <= MAX_OUTLINES;
    let selection = &state.session.selection.particles;
    // Without every outline, only the selection is visited, not the whole scene each frame.
    let shown: Box<dyn Iterator<Item = usize>> =
        if draw_all { Box::new(0..project.particles.len()) } else { Box::new(selection.iter().copied()) };
    for i in shown {
        let Some(p) = project.particles.get(i) else { continue };
        let selected = !draw_all || selection.contains(&i);
        if p.hidden {
            continue;
        }
        if let Some((s, z)) = vp.project(p.center) {
            let r = p.radius * vp.points_per_metre(z);
            if selected {
                painter.circle_stroke(s, r, Line::new(1.5, SELECTED));
            } else {
                painter.add(faint_circle(s, r, outline));
            }
        }
    }
    for (i, l) in project.lights.iter().enumerate() {
        let anchor = project.light_anchor(l);
        let Some((s, _)) = vp.project(anchor) else { continue };
        let c = (l.color / l.color.max_element().max(1e-6) * 255.0).clamp(Vec3::ZERO, Vec3::splat(255.0));
        let fill = Color32::from_rgb(c.x as u8, c.y as u8, c.z as u8);
        let selected = state.session.selection.lights.contains(&i);
        let edge = if selected { SELECTED } else { Color32::from_gray(20) };
        light_direction(project, &vp, painter, l, anchor, if l.hidden { Color32::GRAY } else { fill }, selected);
        for k in 0..8 {
            let a = k as f32 * std::f32::consts::TAU / 8.0;
            let d = egui::vec2(a.cos(), a.sin());
            painter
                .line_segment([s + d * 8.0, s + d * 13.0], Line::new(1.5, if l.hidden { Color32::GRAY } else { fill }));
        }
        painter.circle(
            s,
            6.0,
            if l.hidden { Color32::GRAY } else { fill },
            Line::new(if selected { 2.0 } else { 1.0 }, edge),
        );
    }
    if let Some(Gesture::Box { start }) = &state.view.gesture {
        if let Some(end) = hover {
            painter.rect_stroke(
                Rect::from_two_pos(*start, end),
                0.0,
                Line::new(1.0, SELECTED),
                egui::StrokeKind::Inside,
            );
        }
    }
    if let Some(pos) = hover {
        if matches!(state.view.tool, Tool::Paint | Tool::Erase | Tool::Scale) {
            // Paint previews the brush where the stroke would go: a ring at that depth, sized
            // for it, with its centre marked; a stroke in progress keeps its depth.
            let anchor = match &state.view.gesture {
                Some(Gesture::Paint(stroke)) => stroke.anchor.and_then(|a| vp.on_view_plane(pos, a)),
                _ if state.view.tool == Tool::Paint => state.view.brush_point,
                _ => None,
            };
            let at = anchor.or_else(|| tools::working_plane_point(project, &vp, pos));
            let z = at.and_then(|p| vp.project(p)).map_or(1.0, |(_, z)| z);
            let r = state.view.brush.radius * vp.points_per_metre(z);
            let color = if state.view.tool == Tool::Erase { Color32::from_rgb(255, 90, 90) } else { Color32::WHITE };
            painter.circle_stroke(pos, r, Line::new(1.0, color));
            if anchor.is_some() {
                painter.circle_filled(pos, 2.0, color);
                painter.circle_stroke(pos, r * 0.5, Line::new(1.0, color.gamma_multiply(0.5)));
            }
        }
    }
}

/// The move gizmo: axis arrows and plane squares in the slice-plane colours, the handle under
/// the pointer (or being dragged) lit up, and while dragging the axis line and the drag's
/// values next to the pointer.
pub(super) fn gizmo_overlay(state: &EditorState, painter: &egui::Painter, rect: Rect, pointer: Option<Pos2>) {
    let vp = ViewProjection::new(&state.session.project().camera, rect);
    let Some(g) = shown_gizmo(state, &vp) else { return };
    let (active, drag) = match &state.view.gesture {
        Some(Gesture::Gizmo { handle, applied, snap, .. }) => (Some(*handle), Some((*applied, *snap))),
        None => (pointer.filter(|p| rect.contains(*p)).and_then(|p| g.handle_at(p)), None),
        _ => (None, None),
    };
    let colour = |a: usize, lit: bool| {
        let c = super::slices::Axis::ALL[a].colour();
        if lit {
            gizmo::LIT
        } else {
            c
        }
    };
    if let (Some(handle), Some(_)) = (active, drag) {
        // The line (or the plane's two lines) the drag is held to, across the view.
        let axes: Vec<usize> = match handle {
            Handle::Axis(a) => vec![a],
            Handle::Plane(n) => vec![(n + 1) % 3, (n + 2) % 3],
        };
        for a in axes {
            let far = g.length * 40.0;
            let ends = [g.center - Vec3::AXES[a] * far, g.center + Vec3::AXES[a] * far];
            if let (Some((p, _)), Some((q, _))) = (vp.project(ends[0]), vp.project(ends[1])) {
                painter.line_segment([p, q], Line::new(1.0, colour(a, false).gamma_multiply(0.6)));
            } else if let Some((tip, _)) = vp.project(g.center + Vec3::AXES[a] * g.length) {
                let d = (tip - g.screen).normalized() * 4000.0;
                painter
                    .line_segment([g.screen - d, g.screen + d], Line::new(1.0, colour(a, false).gamma_multiply(0.6)));
            }
        }
    }
    for n in 0..3 {
        let Some(q) = g.square(n) else { continue };
        let lit = active == Some(Handle::Plane(n));
        let c = colour(n, lit);
        let fill = Color32::from_rgba_unmultiplied(c.r(), c.g(), c.b(), if lit { 150 } else { 70 });
        painter.add(egui::Shape::convex_polygon(q.to_vec(), fill, Line::new(1.0, c)));
    }
    for a in 0..3 {
        let Some((from, tip)) = g.arrow(a) else { continue };
        let lit = active == Some(Handle::Axis(a));
        let c = colour(a, lit);
        let dir = (tip - from).normalized();
        let side = egui::vec2(-dir.y, dir.x);
        painter.line_segment([from + dir * 12.0, tip], Line::new(if lit { 4.0 } else { 2.5 }, c));
        let head = if lit { 7.0 } else { 5.5 };
        painter.add(egui::Shape::convex_polygon(
            vec![tip + dir * head * 2.2, tip + side * head, tip - side * head],
            c,
            Line::NONE,
        ));
    }
    painter.circle_stroke(g.screen, 5.0, Line::new(1.5, Color32::WHITE));
    if let (Some((d, snap)), Some(p)) = (drag, pointer) {
        let mut text = format!("Δx {:+.3} m   Δy {:+.3} m   Δz {:+.3} m", d.x, d.y, d.z);
        if snap {
            text.push_str("   (centre snapped to a grid cell)");
        }
        let galley = painter.layout_no_wrap(text, egui::FontId::proportional(13.0), Color32::WHITE);
        let at = p + egui::vec2(18.0, 18.0);
        let at =
            Pos2::new(at.x.min(rect.right() - galley.size().x - 8.0).max(rect.left()), at.y.min(rect.bottom() - 24.0));
        let bg = Rect::from_min_size(at, galley.size()).expand(4.0);
        painter.rect_filled(bg, 3.0, Color32::from_black_alpha(190));
        painter.galley(at, galley, Color32::WHITE);
    }
}
