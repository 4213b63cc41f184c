//! simulated3D (in progress)
