//! The table of every provided interface, by name.

use std::{any::Any, collections::BTreeMap, sync::Arc};

use parking_lot::RwLock;

use super::{
    cell::{AnyInterface, Interface},
    kinds::Kind,
    names::canonical,
    values::InterfaceValue,
};

/// Errors looking up an interface.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum InterfaceError {
    #[error("no interface `{name}` is provided; provided: {available}")]
    Missing { name: String, available: String },
    #[error("interface `{name}` is a {found} interface, not {expected}")]
    WrongType {
        name: String,
        expected: Kind,
        found: Kind,
    },
    #[error("interface `{name}` is already provided by {provider}")]
    Duplicate { name: String, provider: String },
    /// A value that does not fit its interface (a colorA image not 320x240, ...).
    #[error("{0}")]
    Rejected(String),
    /// A recorded or received clock that is not after the current one, or absurd.
    #[error("{0}")]
    Clock(String),
    /// A `set NAME FIELD=VALUE` that names no field or gives no valid value.
    #[error("{0}")]
    Field(String),
}

/// An interface and the order it was provided in.
type Entry = (usize, Arc<dyn AnyInterface>);

/// The table of every provided interface, by name, in the order they were provided.
#[derive(Default)]
pub struct Interfaces {
    table: RwLock<BTreeMap<String, Entry>>,
}

impl Interfaces {
    /// Creates interface `name` for `provider` and returns it. A name can be
    /// provided once.
    pub fn provide<T: InterfaceValue>(
        &self,
        name: &str,
        provider: &str,
    ) -> Result<Arc<Interface<T>>, InterfaceError> {
        self.provide_value(name, provider, T::default())
    }

    /// Like [`provide`](Self::provide) with an initial value (e.g. an image of the right size).
    pub fn provide_value<T: InterfaceValue>(
        &self,
        name: &str,
        provider: &str,
        initial: T,
    ) -> Result<Arc<Interface<T>>, InterfaceError> {
        let name = canonical(name);
        let mut t = self.table.write();
        if let Some((_, i)) = t.get(&name) {
            return Err(InterfaceError::Duplicate {
                name,
                provider: i.provider().to_string(),
            });
        }
        let iface = Arc::new(Interface::with_value(&name, provider, initial));
        let n = t.len();
        t.insert(name, (n, iface.clone()));
        Ok(iface)
    }

    /// The typed interface `name` (aliases accepted).
    pub fn get<T: InterfaceValue>(&self, name: &str) -> Result<Arc<Interface<T>>, InterfaceError> {
        let any = self.get_any(name)?;
        let found = any.kind();
        let any_arc: Arc<dyn Any + Send + Sync> = any;
        any_arc
            .downcast::<Interface<T>>()
            .map_err(|_| InterfaceError::WrongType {
                name: canonical(name),
                expected: T::KIND,
                found,
            })
    }

    /// The interface `name` whatever its type.
    pub fn get_any(&self, name: &str) -> Result<Arc<dyn AnyInterface>, InterfaceError> {
        let name = canonical(name);
        let t = self.table.read();
        t.get(&name)
            .map(|(_, i)| i.clone())
            .ok_or_else(|| InterfaceError::Missing {
                available: if t.is_empty() {
                    "none (load a driver that provides it)".into()
                } else {
                    t.keys().cloned().collect::<Vec<_>>().join(", ")
                },
                name,
            })
    }

    /// Every interface, in the order provided.
    pub fn all(&self) -> Vec<Arc<dyn AnyInterface>> {
        let t = self.table.read();
        let mut v: Vec<_> = t.values().cloned().collect();
        v.sort_by_key(|(i, _)| *i);
        v.into_iter().map(|(_, i)| i).collect()
    }

    /// Names of every interface, in the order provided.
    pub fn names(&self) -> Vec<String> {
        self.all().iter().map(|i| i.name().to_string()).collect()
    }

    /// Names of the interfaces holding `T` (every image interface, ...), in the
    /// order provided.
    pub fn names_of<T: InterfaceValue>(&self) -> Vec<String> {
        self.all()
            .iter()
            .filter(|i| i.kind() == T::KIND)
            .map(|i| i.name().to_string())
            .collect()
    }

    pub fn contains(&self, name: &str) -> bool {
        self.table.read().contains_key(&canonical(name))
    }
}

/// The one interface of a type a schema uses at a time, chosen by name while it
/// runs (a panel's source picker): following a new name resumes that interface and
/// suspends the previous one, so its driver works only for what is watched;
/// [`release`](Self::release) (at stop) suspends it.
pub struct InUse<T> {
    iface: Option<Arc<Interface<T>>>,
}

impl<T> Default for InUse<T> {
    fn default() -> Self {
        InUse { iface: None }
    }
}

impl<T: InterfaceValue> InUse<T> {
    /// The interface `name`, resumed; the previous one, if another, is suspended.
    pub fn follow(
        &mut self,
        table: &Interfaces,
        name: &str,
    ) -> Result<Arc<Interface<T>>, InterfaceError> {
        if let Some(u) = &self.iface
            && u.name() == canonical(name)
        {
            return Ok(u.clone());
        }
        let new = table.get::<T>(name)?;
        new.resume();
        if let Some(old) = self.iface.replace(new.clone()) {
            old.suspend();
        }
        Ok(new)
    }

    /// Stops using the interface (suspends it).
    pub fn release(&mut self) {
        if let Some(u) = self.iface.take() {
            u.suspend();
        }
    }
}
