//! The driver trait: what the runtime keeps of a loaded driver or service. A
//! driver's thread ([`Worker`]) and its supervised devices ([`Supervisor`]) are
//! drivers as they are.

use crate::supervisor::{Supervisor, Worker};

/// A driver or service: the factory provides its interfaces and starts its work;
/// [`Driver::terminate`] stops it (e.g. zeroes the motors, closes the device).
pub trait Driver: Send {
    fn terminate(&mut self) {}
}

impl Driver for Worker {
    fn terminate(&mut self) {
        self.stop();
    }
}

impl Driver for Supervisor {
    fn terminate(&mut self) {
        self.stop();
    }
}

/// A driver with several devices (one per camera) is its supervisors.
impl Driver for Vec<Supervisor> {
    fn terminate(&mut self) {
        for s in self {
            s.stop();
        }
    }
}
