//! What a schema sees of the runtime while it runs.

use std::sync::Arc;

use super::{Arbitration, BrotherGroup, Father, Runtime, RuntimeError, SchemaSlot};
use crate::{interfaces::Interfaces, output};

/// What a schema sees of the runtime.
pub struct Context {
    pub(super) runtime: Arc<Runtime>,
    pub(super) slot: Arc<SchemaSlot>,
}

impl Context {
    /// This schema's name.
    pub fn name(&self) -> &str {
        &self.slot.name
    }
    /// The runtime (interfaces, name space, other schemas).
    pub fn runtime(&self) -> &Arc<Runtime> {
        &self.runtime
    }
    /// The interface table.
    pub fn interfaces(&self) -> &Interfaces {
        &self.runtime.interfaces
    }
    /// Iterations done since loaded.
    pub fn iterations(&self) -> u64 {
        self.slot.stats.lock().timing(false).iterations
    }
    /// Prints a line without garbling the shell.
    pub fn println(&self, line: impl Into<String>) {
        output::println(line);
    }
    /// Runs children (schemas or interfaces) as brothers under this schema, with an
    /// optional arbitration among them. They are stopped when this schema stops.
    pub fn run_children(
        &self,
        names: &[impl AsRef<str>],
        arbitration: Option<Arbitration>,
    ) -> Result<(), RuntimeError> {
        let names: Vec<&str> = names.iter().map(AsRef::as_ref).collect();
        let schema_names: Vec<String> = names
            .iter()
            .filter(|n| self.runtime.schema(n).is_some())
            .map(|n| n.to_string())
            .collect();
        let group = (schema_names.len() > 1 || arbitration.is_some())
            .then(|| BrotherGroup::new(schema_names.clone(), arbitration));
        for name in names {
            let g = group.as_ref().and_then(|g| {
                schema_names
                    .iter()
                    .position(|s| s == name)
                    .map(|i| (g.clone(), i))
            });
            self.runtime
                .run_as(name, Father::Schema(self.slot.name.clone()), g)?;
            self.slot.ctl.lock().children.push(name.to_string());
        }
        Ok(())
    }
}
