//! The GUI host: one eframe window with mastergui and the shown schema panels.

use crate::runtime::Runtime;

/// A schema's GUI panel. It is taken from the schema once, when the schema is
/// loaded, and lives on the GUI thread: it shares state with its schema through
/// interfaces or atomics/`Arc`s, never by locking the schema, so drawing never
/// blocks a schema and a schema never blocks drawing.
pub trait Panel: Send {
    /// Draws the panel.
    fn ui(&mut self, ui: &mut egui::Ui, rt: &Runtime);
}
