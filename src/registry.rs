//! The compile-time component registry.
//!
//! Every driver, service and schema submits a [`Entry`] through `inventory`
//! (with [`register_schema!`](crate::register_schema) or
//! [`register_driver!`](crate::register_driver)), from a module compiled only under
//! the cargo feature of its own name. The conf loader instantiates only what a conf
//! loads. Asking for a component that is not compiled in names the feature that
//! would add it.

use crate::{
    conf::{ComponentConf, Kind, settings::Setting},
    runtime::{Driver, Runtime, Schema},
};

include!(concat!(env!("OUT_DIR"), "/features.rs"));

/// Builds a schema from its conf lines.
pub type SchemaFactory = fn(&ComponentConf, &Runtime) -> anyhow::Result<Box<dyn Schema>>;
/// Builds a driver or service from its conf lines; it provides its interfaces on `Runtime`.
pub type DriverFactory = fn(&ComponentConf, &Runtime) -> anyhow::Result<Box<dyn Driver>>;

/// How to build a component.
#[derive(Clone, Copy)]
pub enum Factory {
    Schema(SchemaFactory),
    Driver(DriverFactory),
}

/// A registered component: what `jderobot list` shows and how to build it.
pub struct Entry {
    pub kind: Kind,
    pub name: &'static str,
    /// One line for `jderobot list` and help texts.
    pub summary: &'static str,
    /// The cargo feature that compiles it in (empty for a user's own crate).
    pub feature: &'static str,
    pub factory: Factory,
    /// The lines it takes, declared once ([`crate::conf::settings`]): `check`
    /// validates them and `jderobot help NAME` prints them. `None` for a component
    /// that takes no lines.
    pub lines: Option<Lines>,
}

/// A component's declared lines: what `jderobot help` prints and what
/// `jderobot check` runs.
#[derive(Clone, Copy)]
pub struct Lines {
    pub decl: &'static [Setting],
    /// Checks a component's lines: against the declaration, then (a
    /// [`Declared`](crate::conf::settings::Declared) component) the typed read.
    pub check: fn(&ComponentConf) -> Vec<crate::conf::ConfError>,
}

impl Lines {
    /// The lines of `T`, a struct made by [`declare_lines!`](crate::declare_lines).
    pub const fn of<T: crate::conf::settings::Declared>() -> Lines {
        Lines {
            decl: T::LINES,
            check: crate::conf::settings::check_declared::<T>,
        }
    }
}

inventory::collect!(Entry);

/// What a component's shell command does, given the runtime and the words after
/// the command; `Err` is the one line the shell prints on standard error.
pub type CommandFn = fn(&Runtime, &[&str], &mut dyn std::io::Write) -> Result<(), String>;

/// A shell command a component brings (the recorder's `record`, replay's `step`),
/// as it brings its conf lines: the shell runs it and lists it in `help`, and
/// `jderobot help COMPONENT` prints it. Registered with
/// [`register_command!`](crate::register_command).
pub struct ShellCommand {
    /// The component that brings it (`recorder`).
    pub component: &'static str,
    pub name: &'static str,
    /// Its arguments, as `help` shows them (`start|stop|status`).
    pub usage: &'static str,
    /// One line of help.
    pub help: &'static str,
    pub run: CommandFn,
}

inventory::collect!(ShellCommand);

/// A line a component adds to the shell's `ps` (`recorder: recording ...`):
/// `None` while it has nothing to say (not loaded). Registered with
/// [`register_ps_line!`](crate::register_ps_line).
pub struct PsLine {
    pub component: &'static str,
    pub line: fn(&Runtime) -> Option<String>,
}

inventory::collect!(PsLine);

/// Every registered shell command, sorted by name.
pub fn commands() -> Vec<&'static ShellCommand> {
    let mut v: Vec<&'static ShellCommand> = inventory::iter::<ShellCommand>.into_iter().collect();
    v.sort_by_key(|c| (c.name, c.component));
    v
}

/// The registered shell command called `name`.
pub fn command(name: &str) -> Option<&'static ShellCommand> {
    inventory::iter::<ShellCommand>
        .into_iter()
        .find(|c| c.name == name)
}

/// Every registered `ps` line, sorted by component.
pub fn ps_lines() -> Vec<&'static PsLine> {
    let mut v: Vec<&'static PsLine> = inventory::iter::<PsLine>.into_iter().collect();
    v.sort_by_key(|p| p.component);
    v
}

/// Registers a component's shell command:
/// `register_command!("recorder", "record", "start|stop|status", "one line of help", run_fn)`
/// with `run_fn: fn(&Runtime, &[&str], &mut dyn Write) -> Result<(), String>`.
#[macro_export]
macro_rules! register_command {
    ($component:literal, $name:literal, $usage:literal, $help:literal, $run:expr) => {
        $crate::inventory::submit! {
            $crate::registry::ShellCommand {
                component: $component,
                name: $name,
                usage: $usage,
                help: $help,
                run: $run,
            }
        }
    };
}

/// Registers a component's `ps` line: `register_ps_line!("recorder", line_fn)` with
/// `line_fn: fn(&Runtime) -> Option<String>` (the shell prints `recorder: LINE`).
#[macro_export]
macro_rules! register_ps_line {
    ($component:literal, $line:expr) => {
        $crate::inventory::submit! {
            $crate::registry::PsLine {
                component: $component,
                line: $line,
            }
        }
    };
}

/// Every compiled-in component, sorted by kind then name.
pub fn components() -> Vec<&'static Entry> {
    let mut v: Vec<&'static Entry> = inventory::iter::<Entry>.into_iter().collect();
    v.sort_by_key(|c| (c.kind as u8, c.name));
    v
}

/// The compiled-in component called `name`.
pub fn find(name: &str) -> Option<&'static Entry> {
    inventory::iter::<Entry>
        .into_iter()
        .find(|c| c.name == name)
}

/// Why a load line names nothing this binary can load; each message says what to do.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum LookupError {
    #[error("`{name}` is a {is}, not a {asked}; load it with `load_{is} {name}`")]
    WrongKind { name: String, is: Kind, asked: Kind },
    /// The component exists as a cargo feature that this binary was built without.
    #[error(
        "{what} `{name}` is not compiled into this binary; rebuild with \
         `cargo build --release --features {name}` (or `--features full`)"
    )]
    NotCompiled { what: String, name: String },
    #[error(
        "no {what} called `{name}`; compiled in: {compiled}; cargo features that add components: {features}"
    )]
    Unknown {
        what: String,
        name: String,
        compiled: String,
        features: String,
    },
}

/// Looks a component up for a load line (`kind` `None` for `load NAME`).
pub fn lookup(kind: Option<Kind>, name: &str) -> Result<&'static Entry, LookupError> {
    // A name may be both a driver and a service (`ros2`): the kind asked picks.
    if let Some(c) = kind.and_then(|k| {
        inventory::iter::<Entry>
            .into_iter()
            .find(|c| c.name == name && c.kind == k)
    }) {
        return Ok(c);
    }
    if let Some(c) = find(name) {
        return match kind {
            Some(k) if !k.same_family(c.kind) => Err(LookupError::WrongKind {
                name: name.into(),
                is: c.kind,
                asked: k,
            }),
            _ => Ok(c),
        };
    }
    let what = kind.map(|k| k.to_string()).unwrap_or("component".into());
    if ALL_COMPONENT_FEATURES.contains(&name) {
        return Err(LookupError::NotCompiled {
            what,
            name: name.into(),
        });
    }
    let compiled: Vec<&str> = components().iter().map(|c| c.name).collect();
    Err(LookupError::Unknown {
        what,
        name: crate::files::shorten(name).into_owned(),
        compiled: compiled.join(", "),
        features: ALL_COMPONENT_FEATURES.join(", "),
    })
}

/// Registers a schema: `register_schema!("name", "summary", factory_fn)`.
///
/// `factory_fn: fn(&ComponentConf, &Runtime) -> anyhow::Result<Box<dyn Schema>>`.
/// The feature is taken to be the name; a user's crate may pass a fourth argument.
/// A last `lines = TYPE` argument names the struct that declares its lines
/// ([`declare_lines!`](crate::declare_lines)).
#[macro_export]
macro_rules! register_schema {
    ($name:literal, $summary:literal, $factory:expr, lines = $lines:ty) => {
        $crate::register_schema!(@ $name, $summary, $factory, $name,
            Some($crate::registry::Lines::of::<$lines>()));
    };
    ($name:literal, $summary:literal, $factory:expr) => {
        $crate::register_schema!(@ $name, $summary, $factory, $name, None);
    };
    ($name:literal, $summary:literal, $factory:expr, $feature:literal, lines = $lines:ty) => {
        $crate::register_schema!(@ $name, $summary, $factory, $feature,
            Some($crate::registry::Lines::of::<$lines>()));
    };
    ($name:literal, $summary:literal, $factory:expr, $feature:literal) => {
        $crate::register_schema!(@ $name, $summary, $factory, $feature, None);
    };
    (@ $name:literal, $summary:literal, $factory:expr, $feature:literal, $lines:expr) => {
        $crate::inventory::submit! {
            $crate::registry::Entry {
                kind: $crate::conf::Kind::Schema,
                name: $name,
                summary: $summary,
                feature: $feature,
                factory: $crate::registry::Factory::Schema($factory),
                lines: $lines,
            }
        }
    };
}

/// Registers a driver or service:
/// `register_driver!(Driver|Service, "name", "summary", factory_fn)`; a fifth
/// argument names the feature when it is not the name (aliases such as `graphics_gtk`);
/// a last `lines = TYPE` argument names the struct that declares its lines.
#[macro_export]
macro_rules! register_driver {
    ($kind:ident, $name:literal, $summary:literal, $factory:expr, lines = $lines:ty) => {
        $crate::register_driver!(@ $kind, $name, $summary, $factory, $name,
            Some($crate::registry::Lines::of::<$lines>()));
    };
    ($kind:ident, $name:literal, $summary:literal, $factory:expr) => {
        $crate::register_driver!(@ $kind, $name, $summary, $factory, $name, None);
    };
    ($kind:ident, $name:literal, $summary:literal, $factory:expr, $feature:literal, lines = $lines:ty) => {
        $crate::register_driver!(@ $kind, $name, $summary, $factory, $feature,
            Some($crate::registry::Lines::of::<$lines>()));
    };
    ($kind:ident, $name:literal, $summary:literal, $factory:expr, $feature:literal) => {
        $crate::register_driver!(@ $kind, $name, $summary, $factory, $feature, None);
    };
    (@ $kind:ident, $name:literal, $summary:literal, $factory:expr, $feature:literal, $lines:expr) => {
        $crate::inventory::submit! {
            $crate::registry::Entry {
                kind: $crate::conf::Kind::$kind,
                name: $name,
                summary: $summary,
                feature: $feature,
                factory: $crate::registry::Factory::Driver($factory),
                lines: $lines,
            }
        }
    };
}
