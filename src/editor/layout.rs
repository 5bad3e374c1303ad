//! The dock's tabs and their default arrangement.

use egui_dock::{DockState, NodeIndex};
use serde::{Deserialize, Serialize};

/// The dockable panels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Tab {
    Viewport,
    Slices,
    Outliner,
    Inspector,
    Stats,
    Timeline,
}

impl Tab {
    pub const ALL: [Tab; 6] = [Tab::Viewport, Tab::Slices, Tab::Outliner, Tab::Inspector, Tab::Stats, Tab::Timeline];
    pub fn title(self) -> &'static str {
        match self {
            Tab::Viewport => "Viewport",
            Tab::Slices => "Slices",
            Tab::Outliner => "Outliner",
            Tab::Inspector => "Inspector",
            Tab::Stats => "Stats",
            Tab::Timeline => "Timeline",
        }
    }
}

/// The least height or width a split leaves a panel, in points: the Timeline's two rows.
pub const MIN_PANEL: f32 = 100.0;

/// The default arrangement: outliner left, viewport centre with the timeline and slices
/// below, inspector and stats right.
pub fn default_layout() -> DockState<Tab> {
    let mut dock = DockState::new(vec![Tab::Viewport]);
    let tree = dock.main_surface_mut();
    let [center, _right] = tree.split_right(NodeIndex::root(), 0.76, vec![Tab::Inspector, Tab::Stats]);
    let [center, _left] = tree.split_left(center, 0.2, vec![Tab::Outliner]);
    let [viewport, _slices] = tree.split_below(center, 0.64, vec![Tab::Slices]);
    tree.split_below(viewport, 0.74, vec![Tab::Timeline]);
    dock
}

/// Opens (in the focused area) or closes a panel.
pub(super) fn set_open(dock: &mut DockState<Tab>, tab: Tab, open: bool) {
    match (dock.find_tab(&tab), open) {
        (Some(path), false) => {
            dock.remove_tab(path);
        }
        (None, true) => {
            if dock.iter_all_tabs().next().is_none() {
                *dock = DockState::new(vec![tab]);
            } else {
                dock.push_to_first_leaf(tab);
            }
        }
        _ => {}
    }
}

/// Puts the Timeline under the viewport, for a layout remembered from before there was one.
pub(super) fn add_timeline(dock: &mut DockState<Tab>) {
    match dock.find_tab(&Tab::Viewport) {
        Some(path) => {
            dock[path.surface].split_below(path.node, 0.8, vec![Tab::Timeline]);
        }
        None => set_open(dock, Tab::Timeline, true),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_layout_without_the_timeline_gets_it_under_the_viewport() {
        let mut dock = DockState::new(vec![Tab::Viewport]);
        dock.main_surface_mut().split_right(NodeIndex::root(), 0.7, vec![Tab::Inspector]);
        add_timeline(&mut dock);
        let timeline = dock.find_tab(&Tab::Timeline).expect("the Timeline was added");
        let viewport = dock.find_tab(&Tab::Viewport).unwrap();
        assert_ne!(timeline.node, viewport.node, "in its own area, not a tab behind the viewport");
        assert_eq!(timeline.node.parent(), viewport.node.parent(), "split off the viewport's area");
        let default = default_layout();
        assert!(default.find_tab(&Tab::Timeline).is_some(), "the default layout has it");
    }
}
