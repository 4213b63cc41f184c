//! opencv (in progress)
