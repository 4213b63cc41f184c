//! vision (in progress).
