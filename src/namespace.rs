//! The seed's `myexport`/`myimport` name space: (component, name) → typed value.
//!
//! A component exports values other components may import, by name and with their
//! Rust type checked at import:
//!
//! ```
//! use jderobot::namespace::Namespace;
//! let ns = Namespace::default();
//! ns.export("introrob", "target", std::sync::Mutex::new((1000.0f32, 0.0f32))).unwrap();
//! let t = ns.import::<std::sync::Mutex<(f32, f32)>>("introrob", "target").unwrap();
//! assert_eq!(t.lock().unwrap().0, 1000.0);
//! assert!(ns.import::<u32>("introrob", "target").is_err()); // wrong type: clear error
//! ```
//!
//! Unlike 4.3, a duplicate export is an error returned to the caller (the first
//! export still wins), and a missing name lists what the component does export.

use std::{any::Any, collections::BTreeMap, sync::Arc};

use parking_lot::RwLock;

struct Entry {
    value: Arc<dyn Any + Send + Sync>,
    type_name: &'static str,
}

/// Errors of the name space.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum NamespaceError {
    #[error("`{component}` already exports `{name}`; the first export stays")]
    Duplicate { component: String, name: String },
    #[error("`{component}` exports no `{name}`; it exports: {available}")]
    Missing {
        component: String,
        name: String,
        available: String,
    },
    #[error("`{component}.{name}` is a `{found}`, not a `{expected}`")]
    WrongType {
        component: String,
        name: String,
        expected: &'static str,
        found: &'static str,
    },
}

/// The shared name space.
#[derive(Default)]
pub struct Namespace {
    entries: RwLock<BTreeMap<(String, String), Entry>>,
}

impl Namespace {
    /// Exports `value` as `component.name`; returns the shared handle.
    pub fn export<T: Any + Send + Sync>(
        &self,
        component: &str,
        name: &str,
        value: T,
    ) -> Result<Arc<T>, NamespaceError> {
        let value = Arc::new(value);
        self.export_arc(component, name, value.clone())?;
        Ok(value)
    }

    /// Exports an already shared value.
    pub fn export_arc<T: Any + Send + Sync>(
        &self,
        component: &str,
        name: &str,
        value: Arc<T>,
    ) -> Result<(), NamespaceError> {
        let key = (component.to_string(), name.to_string());
        let mut e = self.entries.write();
        if e.contains_key(&key) {
            return Err(NamespaceError::Duplicate {
                component: key.0,
                name: key.1,
            });
        }
        e.insert(
            key,
            Entry {
                value,
                type_name: std::any::type_name::<T>(),
            },
        );
        Ok(())
    }

    /// Imports `component.name` as a `T`.
    pub fn import<T: Any + Send + Sync>(
        &self,
        component: &str,
        name: &str,
    ) -> Result<Arc<T>, NamespaceError> {
        let e = self.entries.read();
        let Some(entry) = e.get(&(component.to_string(), name.to_string())) else {
            let available: Vec<&str> = e
                .keys()
                .filter(|(c, _)| c == component)
                .map(|(_, n)| n.as_str())
                .collect();
            return Err(NamespaceError::Missing {
                component: component.into(),
                name: name.into(),
                available: if available.is_empty() {
                    "nothing (is it loaded?)".into()
                } else {
                    available.join(", ")
                },
            });
        };
        entry
            .value
            .clone()
            .downcast::<T>()
            .map_err(|_| NamespaceError::WrongType {
                component: component.into(),
                name: name.into(),
                expected: std::any::type_name::<T>(),
                found: entry.type_name,
            })
    }

    /// Removes everything a component exported (when it terminates).
    pub fn remove_component(&self, component: &str) {
        self.entries.write().retain(|(c, _), _| c != component);
    }

    /// Every (component, name, type) exported.
    pub fn list(&self) -> Vec<(String, String, &'static str)> {
        self.entries
            .read()
            .iter()
            .map(|((c, n), e)| (c.clone(), n.clone(), e.type_name))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_export_wins_and_errors_are_clear() {
        let ns = Namespace::default();
        ns.export("a", "x", 1u32).unwrap();
        assert!(matches!(
            ns.export("a", "x", 2u32),
            Err(NamespaceError::Duplicate { .. })
        ));
        assert_eq!(*ns.import::<u32>("a", "x").unwrap(), 1);
        let e = ns.import::<u32>("a", "y").unwrap_err().to_string();
        assert!(e.contains("exports: x"), "{e}");
        let e = ns.import::<f32>("a", "x").unwrap_err().to_string();
        assert!(e.contains("not a `f32`"), "{e}");
    }
}
