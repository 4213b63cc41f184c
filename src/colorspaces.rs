//! colorspaces (in progress).
