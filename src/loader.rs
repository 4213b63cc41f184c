//! The loader: turns a parsed [`Conf`] into a running [`Runtime`]. It carries out
//! the conf's `load_*`, `run` and `show` directives in file order, builds each
//! component through its registry entry from its own lines, checks a conf without
//! running it (`jderobot check`), and re-creates a schema from a conf (`init`).
//!
//! It is the layer between the [`registry`] (what this binary holds) and the
//! [`runtime`](crate::runtime) (which runs what it is given and knows neither).

use std::{path::Path, sync::Arc};

use crate::{
    conf::{Action, ComponentConf, Conf, ConfError, ConfErrors, Kind, Location},
    interfaces,
    registry::{self, Entry, Factory, LookupError},
    runtime::{Runtime, RuntimeError},
};

/// Why a component could not be loaded; each a one-line explanation.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    #[error(transparent)]
    Lookup(#[from] LookupError),
    #[error(transparent)]
    Runtime(#[from] RuntimeError),
    #[error(transparent)]
    Conf(#[from] ConfErrors),
    #[error("conf file `{file}` of {kind} `{name}` does not exist")]
    MissingFile {
        file: String,
        kind: Kind,
        name: String,
    },
    #[error("{kind} `{name}` failed to start: {source:#}")]
    Start {
        kind: Kind,
        name: String,
        source: anyhow::Error,
    },
}

/// Loads every component of a conf and carries out its `run` and `show` lines, in
/// file order. Stops at the first failure with an error naming its line.
pub fn start(conf: &Conf) -> Result<Arc<Runtime>, ConfError> {
    let rt = Runtime::new(&conf.file);
    if let Err(e) = apply(&rt, conf, true) {
        rt.shutdown();
        return Err(e);
    }
    Ok(rt)
}

/// Carries out a conf's directives in file order: its loads, and its `run` and
/// `show` lines if `run_and_show`.
fn apply(rt: &Runtime, conf: &Conf, run_and_show: bool) -> Result<(), ConfError> {
    for d in &conf.directives {
        let at = |e: &dyn std::fmt::Display| ConfError {
            at: d.at.clone(),
            message: e.to_string(),
        };
        match &d.action {
            Action::Load { kind, name, file } => {
                load(rt, conf, *kind, name, file.as_deref()).map_err(|e| at(&e))?
            }
            Action::Run(name) if run_and_show => rt.run(name).map_err(|e| at(&e))?,
            Action::Show(name) if run_and_show => rt.show(name).map_err(|e| at(&e))?,
            Action::Run(_) | Action::Show(_) => {}
        }
    }
    Ok(())
}

/// Loads component `name` (of `kind`, or any kind for `None`) with its lines from
/// `own_file` or its section in `conf`.
pub fn load(
    rt: &Runtime,
    conf: &Conf,
    kind: Option<Kind>,
    name: &str,
    own_file: Option<&Path>,
) -> Result<(), LoadError> {
    let entry = registry::lookup(kind, name)?;
    if rt.is_loaded(name) {
        return Err(RuntimeError::AlreadyLoaded(name.into()).into());
    }
    if let Some(f) = own_file
        && !f.exists()
    {
        return Err(LoadError::MissingFile {
            file: f.display().to_string(),
            kind: entry.kind,
            name: name.into(),
        });
    }
    let cconf = conf.component_conf(entry.kind, name, own_file)?;
    load_entry(rt, entry, &cconf)
}

/// Loads a registry entry with ready-made lines (for tests and embedding).
pub fn load_entry(rt: &Runtime, entry: &Entry, cconf: &ComponentConf) -> Result<(), LoadError> {
    let fail = |source: anyhow::Error| LoadError::Start {
        kind: entry.kind,
        name: entry.name.into(),
        source,
    };
    match entry.factory {
        Factory::Schema(make) => {
            let schema = make(cconf, rt).map_err(fail)?;
            rt.add_schema(entry.name, entry.summary, schema)?;
        }
        Factory::Driver(make) => {
            let driver = make(cconf, rt).map_err(fail)?;
            rt.add_driver(entry.name, entry.kind, driver)?;
        }
    }
    Ok(())
}

/// Re-creates a schema from a conf file (the shell's `init [conf]`, default the
/// main conf); it keeps its slot, state and statistics.
pub fn reinit(rt: &Runtime, name: &str, conf_file: Option<&Path>) -> Result<(), LoadError> {
    if rt.schema(name).is_none() {
        return Err(rt.not_loaded(name).into());
    }
    let entry = registry::lookup(Some(Kind::Schema), name)?;
    let conf = Conf::load(conf_file.unwrap_or(rt.conf_file()))?;
    let cconf = conf.component_conf(Kind::Schema, name, None)?;
    let Factory::Schema(make) = entry.factory else {
        return Err(LookupError::WrongKind {
            name: name.into(),
            is: entry.kind,
            asked: Kind::Schema,
        }
        .into());
    };
    let schema = make(&cconf, rt).map_err(|source| LoadError::Start {
        kind: Kind::Schema,
        name: name.into(),
        source,
    })?;
    rt.replace_schema(name, schema)?;
    Ok(())
}

/// Checks a conf without running it: every load names a compiled-in component of
/// the right kind whose own file exists, every declared line of each component is
/// right ([`settings::check`]), no component is loaded twice, and every
/// `run`/`show` names something loaded before it. Returns every problem found.
pub fn check(conf: &Conf) -> Vec<ConfError> {
    let mut errors = Vec::new();
    let mut loaded: Vec<(String, Kind)> = Vec::new();
    let mut provided: Vec<String> = Vec::new();
    let err = |at: &Location, m: String| ConfError {
        at: at.clone(),
        message: m,
    };
    for d in &conf.directives {
        match &d.action {
            Action::Load { kind, name, file } => match registry::lookup(*kind, name) {
                Ok(c) => {
                    if loaded.iter().any(|(n, _)| n == name) {
                        errors.push(err(&d.at, format!("`{name}` is loaded twice")));
                    }
                    loaded.push((name.clone(), c.kind));
                    if let Some(f) = file
                        && let Err(problem) = crate::files::check_regular(f)
                    {
                        errors.push(err(
                            &d.at,
                            format!(
                                "conf file `{}` of {} `{name}` {problem}",
                                f.display(),
                                c.kind
                            ),
                        ));
                    }
                    if let Ok(cc) = conf.component_conf(c.kind, name, file.as_deref()) {
                        if let Some(lines) = c.lines {
                            errors.extend((lines.check)(&cc));
                        }
                        for l in cc.provides() {
                            if let Some(i) = l.args().first() {
                                provided.push(interfaces::canonical(i));
                            }
                        }
                    }
                }
                Err(m) => errors.push(err(&d.at, m.to_string())),
            },
            Action::Run(name) | Action::Show(name) => {
                let is_schema = loaded.iter().any(|(n, k)| n == name && *k == Kind::Schema);
                let base = interfaces::canonical(name.split('.').next().unwrap_or(name));
                let is_iface = provided.contains(&base)
                    || (interfaces::family(name).is_some()
                        && loaded.iter().any(|(_, k)| *k != Kind::Schema));
                let show = matches!(d.action, Action::Show(_));
                if !(is_schema || (!show && is_iface)) {
                    let verb = if show { "show" } else { "run" };
                    errors.push(err(
                        &d.at,
                        format!(
                            "`{verb} {name}`: no schema `{name}` is loaded before this line; \
                             add `load_schema {name}` above it"
                        ),
                    ));
                }
            }
        }
    }
    errors
}

/// Builds every component of a conf as a run would (each reads its lines and
/// files, and a driver opens its device), without running or showing anything,
/// then shuts them down: what `jderobot check` does once [`check`] finds nothing.
/// Returns the first component that fails, with its line.
pub fn check_loads(conf: &Conf) -> Result<(), ConfError> {
    let rt = Runtime::new(&conf.file);
    let result = apply(&rt, conf, false);
    rt.shutdown();
    result
}
