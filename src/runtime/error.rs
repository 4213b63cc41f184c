//! Errors of run-time operations.

/// Errors of run-time operations, each a one-line explanation.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum RuntimeError {
    #[error("`{name}` is not loaded; loaded: {loaded}")]
    NotLoaded { name: String, loaded: String },
    #[error("`{0}` is not running")]
    NotRunning(String),
    #[error("`{0}` is already running")]
    AlreadyRunning(String),
    #[error("`{0}` is already loaded")]
    AlreadyLoaded(String),
    #[error("`{0}` is an interface; only schemas can be {1}")]
    NotASchema(String, &'static str),
    #[error(transparent)]
    Interface(#[from] crate::interfaces::InterfaceError),
    #[error("{name}: cannot start its thread: {message}")]
    Thread { name: String, message: String },
}
