//! The driver trait: what the runtime keeps of a loaded driver or service.

/// A driver or service: the factory provides its interfaces and starts its work;
/// [`Driver::terminate`] stops it (e.g. zeroes the motors, closes the device).
pub trait Driver: Send {
    fn terminate(&mut self) {}
}
