//! Scripted runs: `--screenshot` saves the window once the preview is on screen and
//! `--measure-fps` redraws still then orbiting and prints the frame rates, both then
//! exiting; `--scripted-stroke` paints one stroke at start.

use super::state::EditorState;
use egui::Context;
use std::time::Instant;

impl EditorState {
    /// `--scripted-stroke`: paints `n` particles as one stroke across the grid's centre.
    pub(super) fn scripted_stroke(&mut self, n: usize) {
        let g = self.session.project().grid;
        let (centre, span) = ((g.min + g.max) * 0.5, (g.max - g.min) * 0.3);
        let tag = self.session.new_tag();
        self.session.add_particles(
            tag,
            (0..n).map(|i| {
                let f = if n > 1 { i as f32 / (n - 1) as f32 - 0.5 } else { 0.0 };
                crate::scene::Particle::new(centre + span * f, span.min_element() * 0.2, 2.0)
            }),
        );
        self.session.end_edit();
    }

    /// `--screenshot` and `--measure-fps` runs.
    pub(super) fn run_scripted(&mut self, ctx: &Context) {
        if let Some(path) = self.options.screenshot.clone() {
            let ready = self.gpu.as_ref().is_none_or(|g| g.renders > 0 || g.error.is_some());
            if ready && self.frames > 5 && !self.scripted.screenshot_requested {
                self.scripted.screenshot_requested = true;
                ctx.send_viewport_cmd(egui::ViewportCommand::Screenshot(egui::UserData::default()));
            }
            let shot = ctx.input(|i| {
                i.raw.events.iter().find_map(|e| match e {
                    egui::Event::Screenshot { image, .. } => Some(image.clone()),
                    _ => None,
                })
            });
            if let Some(image) = shot {
                let bytes: Vec<u8> = image.pixels.iter().flat_map(|c| c.to_array()).collect();
                let [w, h] = image.size;
                let result = image::RgbaImage::from_raw(w as u32, h as u32, bytes)
                    .ok_or_else(|| "screenshot has the wrong size".to_string())
                    .and_then(|img| img.save(&path).map_err(|e| e.to_string()));
                match result {
                    Ok(()) => eprintln!("fogsmith: screenshot saved to {}", path.display()),
                    Err(e) => eprintln!("fogsmith: could not save the screenshot {}: {e}", path.display()),
                }
                self.quit_confirmed = true;
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            ctx.request_repaint();
        }
        if let Some(seconds) = self.options.measure_fps {
            let ready = self.gpu.as_ref().is_none_or(|g| g.renders > 0);
            if !ready || self.frames < 10 {
                return;
            }
            let start = *self.scripted.measure_start.get_or_insert_with(Instant::now);
            let t = start.elapsed().as_secs_f32();
            if t < seconds * 0.5 {
                self.scripted.measure_frames[0] += 1;
            } else if t < seconds {
                self.scripted.measure_frames[1] += 1;
                let camera = super::view::orbit(&self.session.project().camera, 0.02, 0.0);
                self.session.set_camera(camera);
                self.view.force_interacting = true;
                self.view.interacting = true;
            } else {
                self.view.force_interacting = false;
                self.view.interacting = false;
                let half = seconds * 0.5;
                let p = self.session.project();
                println!(
                    "fps: still {:.1}, orbiting {:.1} ({} particles, {} lights, grid {:?}, preview {}x{})",
                    self.scripted.measure_frames[0] as f32 / half,
                    self.scripted.measure_frames[1] as f32 / half,
                    p.particles.len(),
                    p.lights.len(),
                    p.grid.resolution.to_array(),
                    self.view.preview_size[0],
                    self.view.preview_size[1]
                );
                if let Some(g) = &self.gpu {
                    let t = g.report.timings_ms;
                    println!(
                        "last update: {:.1} ms wall; inject {:.1} ms, propagate {:.1} ms, march {:.1} ms at {:?}; {}",
                        g.update_ms,
                        t.inject,
                        t.propagate,
                        t.march,
                        g.texture.map(|t| t.1),
                        g.pipeline.context().adapter_summary()
                    );
                }
                self.options.measure_fps = None;
                self.quit_confirmed = true;
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            ctx.request_repaint();
        }
    }
}
