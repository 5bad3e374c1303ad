//! The editor's commands, in one table: each has its text, tooltip and keyboard shortcuts,
//! and every menu item, the key dispatch and the Help → Shortcuts sheet are generated from
//! it (after rerun's `UICommand`). What a command does is
//! [`EditorState::run`](super::state::EditorState::run).

use super::layout::Tab;
use super::tools::Tool;
use egui::{Key, KeyboardShortcut, ModifierNames, Modifiers};
use strum::{EnumCount, VariantArray};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, EnumCount, VariantArray)]
pub enum Command {
    New,
    Open,
    Save,
    SaveAs,
    ImportVdb,
    /// File → Export…: the Export window.
    Export,
    Revert,
    /// Drop the imported VDB grid (shown only while there is one).
    RemoveBaseVolume,
    Quit,
    Undo,
    Redo,
    SelectAll,
    Duplicate,
    Delete,
    /// Cancel grab/scale, else clear the selection.
    Escape,
    Grab,
    ScaleSelection,
    FitGrid,
    ToolSelect,
    ToolPaint,
    ToolScale,
    ToolErase,
    ToolLight,
    FrameSelection,
    ViewFront,
    ViewRight,
    ViewTop,
    ViewBack,
    ViewLeft,
    ZoomIn,
    ZoomOut,
    SliceNext,
    SlicePrevious,
    /// View → Panels: show or hide one dockable panel.
    PanelViewport,
    PanelSlices,
    PanelOutliner,
    PanelInspector,
    PanelStats,
    PanelTimeline,
    ResetLayout,
    /// View toggles, shown as check boxes.
    ParticleOutlines,
    SlicePlane,
    MoveGizmo,
    /// Animation: give a still project a frame range.
    Animate,
    PlayPause,
    PreviousFrame,
    NextFrame,
    FirstFrame,
    LastFrame,
    /// K: key every animatable value of the selection at the current frame.
    InsertKey,
    /// Delete the keys of the selected timeline marker.
    DeleteKeys,
    /// Toggles, shown as check boxes.
    AutoKey,
    LoopPlayback,
    PlayEveryFrame,
    /// Preview: one ray per pixel instead of adaptive image sampling.
    PerPixelMarch,
    Shortcuts,
}

const fn key(k: Key) -> KeyboardShortcut {
    KeyboardShortcut::new(Modifiers::NONE, k)
}
const fn cmd(k: Key) -> KeyboardShortcut {
    KeyboardShortcut::new(Modifiers::COMMAND, k)
}
const fn shift(k: Key) -> KeyboardShortcut {
    KeyboardShortcut::new(Modifiers::SHIFT, k)
}
const fn cmd_shift(k: Key) -> KeyboardShortcut {
    KeyboardShortcut::new(Modifiers::COMMAND.plus(Modifiers::SHIFT), k)
}

impl Command {
    /// Every command, in declaration order.
    pub const ALL: [Command; Command::COUNT] = {
        let mut all = [Command::New; Command::COUNT];
        let mut i = 0;
        while i < Command::COUNT {
            all[i] = Command::VARIANTS[i];
            i += 1;
        }
        all
    };

    /// The command that picks `tool` (its shortcut lives here).
    pub fn for_tool(tool: Tool) -> Command {
        match tool {
            Tool::Select => Command::ToolSelect,
            Tool::Paint => Command::ToolPaint,
            Tool::Scale => Command::ToolScale,
            Tool::Erase => Command::ToolErase,
            Tool::Light => Command::ToolLight,
        }
    }

    /// The tool this command picks, if it picks one.
    pub fn tool(self) -> Option<Tool> {
        Tool::ALL.into_iter().find(|&t| Command::for_tool(t) == self)
    }

    /// The command that shows or hides `tab`.
    pub fn for_panel(tab: Tab) -> Command {
        match tab {
            Tab::Viewport => Command::PanelViewport,
            Tab::Slices => Command::PanelSlices,
            Tab::Outliner => Command::PanelOutliner,
            Tab::Inspector => Command::PanelInspector,
            Tab::Stats => Command::PanelStats,
            Tab::Timeline => Command::PanelTimeline,
        }
    }

    /// The panel this command shows or hides, if it is a panel toggle.
    pub fn panel(self) -> Option<Tab> {
        Tab::ALL.into_iter().find(|&t| Command::for_panel(t) == self)
    }

    /// (menu text, tooltip); an empty tooltip shows none.
    pub fn text_and_tooltip(self) -> (&'static str, &'static str) {
        match self {
            Command::New => ("New", "Start an empty project"),
            Command::Open => ("Open…", "Open a .ron project"),
            Command::Save => ("Save", "Save (keeps the previous file as .bak)"),
            Command::SaveAs => ("Save As…", "Save under a new name"),
            Command::ImportVdb => ("Import VDB…", "Use a density grid from an OpenVDB file as the base of the fog"),
            Command::Export => ("Export…", "Write the fog as OpenVDB, USD, KTX2 or EXR, or the rendered image: choose the format and its options, then where"),
            Command::Revert => ("Revert", "Reload the file, dropping unsaved changes"),
            Command::RemoveBaseVolume => ("Remove base volume", "Drop the imported VDB grid from the fog"),
            Command::Quit => ("Quit", "Close the editor (asks about unsaved changes)"),
            Command::Undo => ("Undo", "Take back the last edit"),
            Command::Redo => ("Redo", "Bring back the edit undone last"),
            Command::SelectAll => ("Select all", "Select every particle and light"),
            Command::Duplicate => ("Duplicate", "Copy the selection, slightly offset, and select the copies"),
            Command::Delete => ("Delete", "Delete the selection (with a key marker selected in the Timeline: its keys)"),
            Command::Escape => ("Cancel / deselect", "Cancel grab or scale, or close the Export or Shortcuts window; otherwise clear the selection"),
            Command::Grab => ("Grab", "Move the selection with the mouse (pointer over the viewport); click confirms, Esc cancels"),
            Command::ScaleSelection => ("Scale", "Scale the selected particles with the mouse (pointer over the viewport)"),
            Command::FitGrid => ("Fit grid to particles", "Resize the grid box to hold every visible particle (keeps the cell size or the resolution, as chosen in the viewport's warning)"),
            Command::ToolSelect => (Tool::Select.label(), Tool::Select.tooltip()),
            Command::ToolPaint => (Tool::Paint.label(), Tool::Paint.tooltip()),
            Command::ToolScale => (Tool::Scale.label(), Tool::Scale.tooltip()),
            Command::ToolErase => (Tool::Erase.label(), Tool::Erase.tooltip()),
            Command::ToolLight => (Tool::Light.label(), Tool::Light.tooltip()),
            Command::FrameSelection => ("Frame selection", "Aim the camera at the selection (or the whole grid)"),
            Command::ViewFront => ("Front", "Look along −z"),
            Command::ViewRight => ("Right", "Look along −x"),
            Command::ViewTop => ("Top", "Look down −y"),
            Command::ViewBack => ("Back", ""),
            Command::ViewLeft => ("Left", ""),
            Command::ZoomIn => ("Zoom in", "Move the camera towards its target"),
            Command::ZoomOut => ("Zoom out", "Move the camera away from its target"),
            Command::SliceNext => ("Next slice", "Step the Slices panel one cell up its axis"),
            Command::SlicePrevious => ("Previous slice", "Step the Slices panel one cell down its axis"),
            Command::PanelViewport => (Tab::Viewport.title(), "Show or hide this panel"),
            Command::PanelSlices => (Tab::Slices.title(), "Show or hide this panel"),
            Command::PanelOutliner => (Tab::Outliner.title(), "Show or hide this panel"),
            Command::PanelInspector => (Tab::Inspector.title(), "Show or hide this panel"),
            Command::PanelStats => (Tab::Stats.title(), "Show or hide this panel"),
            Command::PanelTimeline => (Tab::Timeline.title(), "Show or hide this panel"),
            Command::ResetLayout => ("Reset layout", "Back to the default arrangement of panels"),
            Command::ParticleOutlines => ("Particle outlines", "Outline every particle in the viewport; when off, only the selection is outlined"),
            Command::SlicePlane => ("Slice plane", "Show the Slices panel's plane in the viewport, in its axis colour"),
            Command::MoveGizmo => ("Move gizmo", "With the Select tool, arrows and squares at the selection's centre: drag one to move along that axis or in that plane (Ctrl snaps the centre to a grid cell's centre; Esc or right click cancels)"),
            Command::Animate => ("Animate", "Give this still project a frame range (frames 1–120 at 24 fps) to key values on"),
            Command::PlayPause => ("Play / pause", "Play the animation in the preview, or stop"),
            Command::PreviousFrame => ("Previous frame", "Show the frame before"),
            Command::NextFrame => ("Next frame", "Show the frame after"),
            Command::FirstFrame => ("First frame", "Show the first frame of the range"),
            Command::LastFrame => ("Last frame", "Show the last frame of the range"),
            Command::InsertKey => ("Key selection", "Key every animatable value of the selected particles and lights at this frame"),
            Command::DeleteKeys => ("Delete keys", "Delete the keys of the marker selected in the Timeline"),
            Command::AutoKey => ("Auto-key", "Edits of animated values set a key at this frame; when off, such an edit on a frame without a key lasts only until the frame changes"),
            Command::LoopPlayback => ("Loop", "Play from the start again after the last frame"),
            Command::PlayEveryFrame => ("Play every frame", "Show every frame converged before the next, instead of keeping time by dropping frames"),
            Command::PerPixelMarch => ("March every pixel", "March one camera ray through every pixel instead of adaptive image sampling (rays a few pixels apart, refined where the fog or the geometry changes, the rest interpolated): several times slower, for comparison"),
            Command::Shortcuts => ("Shortcuts", "All keyboard and mouse shortcuts"),
        }
    }

    pub fn text(self) -> &'static str {
        self.text_and_tooltip().0
    }
    pub fn tooltip(self) -> &'static str {
        self.text_and_tooltip().1
    }

    /// The keyboard shortcuts, the first one shown in menus.
    pub fn shortcuts(self) -> Vec<KeyboardShortcut> {
        match self {
            Command::New => vec![cmd(Key::N)],
            Command::Open => vec![cmd(Key::O)],
            Command::Save => vec![cmd(Key::S)],
            Command::SaveAs => vec![cmd_shift(Key::S)],
            Command::Export => vec![cmd(Key::E)],
            Command::Undo => vec![cmd(Key::Z)],
            Command::Redo => vec![cmd_shift(Key::Z), cmd(Key::Y)],
            Command::SelectAll => vec![cmd(Key::A)],
            Command::Duplicate => vec![cmd(Key::D)],
            Command::Delete => vec![key(Key::Delete), key(Key::X), key(Key::Backspace)],
            Command::Escape => vec![key(Key::Escape)],
            Command::Grab => vec![key(Key::G)],
            Command::ScaleSelection => vec![key(Key::S)],
            Command::ToolSelect => vec![key(Key::Q)],
            Command::ToolPaint => vec![key(Key::B)],
            Command::ToolScale => vec![key(Key::R)],
            Command::ToolErase => vec![key(Key::E)],
            Command::ToolLight => vec![key(Key::L)],
            Command::FrameSelection => vec![key(Key::F)],
            Command::ViewFront => vec![key(Key::Num1)],
            Command::ViewRight => vec![key(Key::Num3)],
            Command::ViewTop => vec![key(Key::Num7)],
            Command::ZoomIn => vec![key(Key::Plus), key(Key::Equals)],
            Command::ZoomOut => vec![key(Key::Minus)],
            Command::SliceNext => vec![key(Key::CloseBracket), key(Key::PageUp)],
            Command::SlicePrevious => vec![key(Key::OpenBracket), key(Key::PageDown)],
            Command::Shortcuts => vec![key(Key::F1)],
            Command::PlayPause => vec![key(Key::Space)],
            Command::PreviousFrame => vec![key(Key::ArrowLeft)],
            Command::NextFrame => vec![key(Key::ArrowRight)],
            Command::FirstFrame => vec![key(Key::Home), shift(Key::ArrowLeft)],
            Command::LastFrame => vec![key(Key::End), shift(Key::ArrowRight)],
            Command::InsertKey => vec![key(Key::K)],
            Command::ImportVdb
            | Command::Revert
            | Command::RemoveBaseVolume
            | Command::Quit
            | Command::FitGrid
            | Command::ViewBack
            | Command::ViewLeft
            | Command::PanelViewport
            | Command::PanelSlices
            | Command::PanelOutliner
            | Command::PanelInspector
            | Command::PanelStats
            | Command::PanelTimeline
            | Command::ResetLayout
            | Command::ParticleOutlines
            | Command::SlicePlane
            | Command::MoveGizmo
            | Command::Animate
            | Command::DeleteKeys
            | Command::AutoKey
            | Command::LoopPlayback
            | Command::PlayEveryFrame
            | Command::PerPixelMarch => vec![],
        }
    }

    /// Whether the shortcut works while a text field has the keyboard.
    pub fn works_while_typing(self) -> bool {
        matches!(self, Command::Save | Command::SaveAs)
    }

    /// Whether the command acts at the pointer and so needs it over the viewport.
    pub fn needs_pointer_in_viewport(self) -> bool {
        matches!(self, Command::Grab | Command::ScaleSelection)
    }

    /// The shortcuts as the menus and the help sheet show them ("Ctrl+Shift+S / Ctrl+Y").
    pub fn shortcut_text(self) -> String {
        self.shortcuts().iter().map(format_shortcut).collect::<Vec<_>>().join(" / ")
    }

    /// A menu button for the command, with its shortcut and tooltip; true when clicked.
    pub fn menu_button(self, ui: &mut egui::Ui, enabled: bool) -> bool {
        self.menu_button_text(ui, enabled, self.text())
    }

    /// [`Self::menu_button`] with other text (Undo with the step's name).
    pub fn menu_button_text(self, ui: &mut egui::Ui, enabled: bool, text: &str) -> bool {
        let button = match self.shortcuts().first() {
            Some(shortcut) => egui::Button::new(text).shortcut_text(format_shortcut(shortcut)),
            None => egui::Button::new(text),
        };
        let response = ui.add_enabled(enabled, button);
        self.with_tooltip(response).clicked()
    }

    /// A menu check box for a toggle command, showing `checked`; true when clicked.
    pub fn menu_checkbox(self, ui: &mut egui::Ui, checked: bool) -> bool {
        let mut value = checked;
        self.with_tooltip(ui.checkbox(&mut value, self.text())).changed()
    }

    fn with_tooltip(self, response: egui::Response) -> egui::Response {
        match self.tooltip() {
            "" => response,
            tip => response.on_hover_text(tip),
        }
    }

    /// The commands whose shortcut was pressed this frame, consuming those key presses.
    /// Shortcuts with more modifiers are matched first (Ctrl+Shift+S before Ctrl+S), and
    /// plain keys never fire while Ctrl/Cmd is held.
    pub fn pressed(ctx: &egui::Context, typing: bool, pointer_in_viewport: bool) -> Vec<Command> {
        let mut table: Vec<(KeyboardShortcut, Command)> =
            Self::ALL.iter().flat_map(|&c| c.shortcuts().into_iter().map(move |s| (s, c))).collect();
        let weight = |m: Modifiers| m.command as u8 + m.shift as u8 + m.alt as u8;
        table.sort_by_key(|(s, _)| std::cmp::Reverse(weight(s.modifiers)));
        let command_held = ctx.input(|i| i.modifiers.command);
        let mut out = Vec::new();
        for (shortcut, c) in table {
            if out.contains(&c)
                || (typing && !c.works_while_typing())
                || (c.needs_pointer_in_viewport() && !pointer_in_viewport)
            {
                continue;
            }
            if shortcut.modifiers.is_none() && command_held {
                continue;
            }
            // Escape closes an open drop-down or menu first (egui reads the key itself).
            if c == Command::Escape && egui::Popup::is_any_open(ctx) {
                continue;
            }
            if ctx.input_mut(|i| i.consume_shortcut(&shortcut)) {
                out.push(c);
            }
        }
        out
    }
}

/// "Ctrl+Shift+S", the same on every platform (the help sheet and tests read it).
pub fn format_shortcut(s: &KeyboardShortcut) -> String {
    s.format(&ModifierNames::NAMES, false)
}

/// Mouse gestures and held keys: not commands, listed on the help sheet after them.
pub const GESTURES: &[(&str, &str)] = &[
    ("Middle drag / right drag", "Orbit"),
    ("Shift + middle / right drag", "Pan"),
    ("Wheel", "Zoom (with the Scale tool: scale; Ctrl + wheel zooms)"),
    ("Arrow keys (held)", "Orbit (in an animated project Left / Right step frames instead)"),
    ("Alt (Scale tool)", "Change density instead of radius"),
    ("Shift / Ctrl + click", "Add to / toggle the selection"),
    ("Drag a gizmo arrow / square", "Move the selection along that axis / in that plane"),
    ("Ctrl (gizmo drag)", "Snap the move to the grid cell"),
    ("Esc / right click (gizmo drag)", "Cancel the move"),
];

/// The Help → Shortcuts sheet: (keys, what they do), every command with a shortcut first.
impl Command {
    /// The command's line on the help sheet: its menu text, told apart where two read alike
    /// (the Scale tool and scaling the selection).
    pub fn sheet_text(self) -> String {
        match self.tool() {
            Some(_) => format!("{} tool", self.text()),
            None if self == Command::ScaleSelection => "Scale the selection".into(),
            None => self.text().to_string(),
        }
    }
}

pub fn help_sheet() -> Vec<(String, String)> {
    Command::ALL
        .iter()
        .filter(|c| !c.shortcuts().is_empty())
        .map(|c| (c.shortcut_text(), c.sheet_text()))
        .chain(GESTURES.iter().map(|(k, v)| (k.to_string(), v.to_string())))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_two_lines_of_the_help_sheet_read_alike() {
        let sheet = help_sheet();
        for (i, (_, text)) in sheet.iter().enumerate() {
            assert!(!sheet[..i].iter().any(|(_, t)| t == text), "{text:?} is on the sheet twice");
        }
    }

    #[test]
    fn all_lists_every_command_once_and_the_mappings_round_trip() {
        for (i, c) in Command::ALL.iter().enumerate() {
            assert!(!Command::ALL[..i].contains(c), "{c:?} is listed twice");
            assert!(!c.text().is_empty(), "{c:?} has a menu text");
        }
        for tool in Tool::ALL {
            assert_eq!(Command::for_tool(tool).tool(), Some(tool));
        }
        for tab in Tab::ALL {
            assert_eq!(Command::for_panel(tab).panel(), Some(tab));
        }
        assert_eq!(Command::ALL.iter().filter(|c| c.tool().is_some()).count(), Tool::ALL.len());
        assert_eq!(Command::ALL.iter().filter(|c| c.panel().is_some()).count(), Tab::ALL.len());
    }

    #[test]
    fn playback_and_frame_keys_never_fire_while_typing() {
        for c in [
            Command::PlayPause,
            Command::PreviousFrame,
            Command::NextFrame,
            Command::FirstFrame,
            Command::LastFrame,
            Command::InsertKey,
        ] {
            assert!(!c.works_while_typing(), "{c:?}");
            for s in c.shortcuts() {
                let ctx = egui::Context::default();
                let event = egui::Event::Key {
                    key: s.logical_key,
                    physical_key: None,
                    pressed: true,
                    repeat: false,
                    modifiers: s.modifiers,
                };
                let input = egui::RawInput { events: vec![event], ..Default::default() };
                let mut got = vec![Command::New];
                let _ = ctx.run_ui(input, |ui| got = Command::pressed(ui.ctx(), true, true));
                assert!(got.is_empty(), "{} while typing", format_shortcut(&s));
            }
        }
    }
}
