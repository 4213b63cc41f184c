//! Where components' messages go.
//!
//! Schemas and drivers print through [`println`] (or the [`jde_println!`] macro)
//! rather than `std::println!`, so that when the interactive shell is editing a
//! line the message is printed above the prompt instead of garbling it. Without a
//! shell, messages go to standard output, one line each.

use std::io::Write;

use parking_lot::Mutex;

type Sink = Box<dyn FnMut(String) + Send>;

static SINK: Mutex<Option<Sink>> = Mutex::new(None);

/// Prints one line of a component's output.
pub fn println(line: impl Into<String>) {
    let line = line.into();
    let mut sink = SINK.lock();
    match sink.as_mut() {
        Some(f) => f(line),
        None => {
            let mut out = std::io::stdout().lock();
            let _ = writeln!(out, "{line}");
        }
    }
}

/// Routes component output to `sink` (the shell's printer); `None` restores stdout.
pub fn set_sink(sink: Option<Sink>) {
    *SINK.lock() = sink;
}

/// `println!` for components: formats and prints one line through [`println`].
#[macro_export]
macro_rules! jde_println {
    ($($arg:tt)*) => { $crate::output::println(format!($($arg)*)) };
}
