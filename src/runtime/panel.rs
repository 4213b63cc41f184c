//! The panel trait: a schema's piece of the GUI window. It is defined here, beside
//! [`Schema`](super::Schema), so a schema can offer a panel without the runtime
//! knowing the GUI host; the host (`crate::gui`) draws the shown panels.

use super::Runtime;

/// A schema's GUI panel. It is taken from the schema once, when the schema is
/// loaded, and lives on the GUI thread: it shares state with its schema through
/// interfaces or atomics/`Arc`s, never by locking the schema, so drawing never
/// blocks a schema and a schema never blocks drawing.
pub trait Panel: Send {
    /// Draws the panel.
    fn ui(&mut self, ui: &mut egui::Ui, rt: &Runtime);
    /// The panel's title (default: the schema's name).
    fn title(&self) -> Option<String> {
        None
    }
    /// Whether the panel is docked in the window's left side panel (mastergui)
    /// rather than shown as a movable window.
    fn docked(&self) -> bool {
        false
    }
}
