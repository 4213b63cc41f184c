//! progeo (in progress).
