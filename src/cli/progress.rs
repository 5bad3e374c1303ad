//! Long commands on a terminal: an indicatif bar on stderr per stage (only when stderr is a
//! terminal and `--quiet` is not given, so `--json` on stdout never changes), and Ctrl+C,
//! which stops the work at the next work item instead of killing the process.

use crate::gpu::Progress;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// Exit status of a command stopped by Ctrl+C (128 + SIGINT, as shells report it).
pub const CANCELLED_EXIT: u8 = 130;

/// Turns Ctrl+C into a request to stop (see [`interrupted`]); a second Ctrl+C while the
/// first is being honoured ends the process at once.
pub fn catch_interrupt() {
    let _ = ctrlc::set_handler(|| {
        if INTERRUPTED.swap(true, Ordering::SeqCst) {
            std::process::exit(CANCELLED_EXIT as i32);
        }
    });
}

/// Whether Ctrl+C was pressed.
pub fn interrupted() -> bool {
    INTERRUPTED.load(Ordering::SeqCst)
}

/// A command was stopped by Ctrl+C; nothing it would have written was changed.
#[derive(Debug, thiserror::Error)]
#[error("cancelled by Ctrl+C; no output file was changed")]
pub struct Cancelled;

/// Fails with [`Cancelled`] once Ctrl+C was pressed.
pub fn check() -> Result<(), Cancelled> {
    if interrupted() {
        Err(Cancelled)
    } else {
        Ok(())
    }
}

/// One bar whose message is the current stage and whose position is the stage's fraction.
/// In a sequence of frames the bar spans the whole sequence and its message names the frame.
pub struct Bar {
    bar: Option<ProgressBar>,
    stage: String,
    /// The frame being baked: its place in the sequence, the sequence's length, its number.
    frame: Option<(usize, usize, Option<i32>)>,
}

const SCALE: u64 = 1000;

impl Bar {
    /// A bar on stderr, or a silent one when stderr is not a terminal or `quiet`.
    pub fn new(quiet: bool) -> Self {
        let bar = (!quiet && std::io::stderr().is_terminal()).then(|| {
            let bar = ProgressBar::with_draw_target(Some(SCALE), ProgressDrawTarget::stderr());
            bar.set_style(
                ProgressStyle::with_template("{msg:>24} [{bar:32}] {percent:>3}%  {elapsed} elapsed, ~{eta} left")
                    .expect("a valid template")
                    .progress_chars("=> "),
            );
            bar
        });
        Self { bar, stage: String::new(), frame: None }
    }

    /// Shows `fraction` (in [0, 1]) of stage `name`; a new stage restarts the bar, except
    /// within a sequence of frames, where the bar shows the whole sequence's progress.
    pub fn stage(&mut self, name: &str, fraction: f64) {
        let Some(bar) = &self.bar else { return };
        let fraction = fraction.clamp(0.0, 1.0);
        let (message, position, restart) = match self.frame {
            Some((k, n, frame)) if n > 1 => {
                let number = frame.map_or(String::new(), |f| format!("frame {f} "));
                (format!("{number}({}/{n}) {name}", k + 1), (k as f64 + fraction) / n as f64, false)
            }
            _ => (name.to_string(), fraction, true),
        };
        if message != self.stage {
            self.stage = message;
            bar.set_message(self.stage.clone());
            if restart {
                bar.reset();
            }
        }
        bar.set_position((position * SCALE as f64) as u64);
    }

    /// Starts frame `frame`, the `k`-th (from 0) of `count`.
    pub fn frame(&mut self, k: usize, count: usize, frame: Option<i32>) {
        self.frame = Some((k, count, frame));
    }

    /// Shows the pipeline's progress; returns false once Ctrl+C asks to stop.
    pub fn pipeline(&mut self, p: &Progress) -> bool {
        let name = p.stage.name();
        self.stage(&name, p.stage_fraction);
        !interrupted()
    }

    /// Runs `f` (which prints) with the bar hidden.
    pub fn suspend(&self, f: impl FnOnce()) {
        match &self.bar {
            Some(bar) => bar.suspend(f),
            None => f(),
        }
    }

    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

impl Drop for Bar {
    fn drop(&mut self) {
        self.finish();
    }
}
