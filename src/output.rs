//! Where components' messages go.
//!
//! Schemas and drivers print through [`println()`] (or the [`jde_println!`](crate::jde_println) macro)
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
    if let Some(f) = sink.as_mut() {
        f(line);
        return;
    }
    // Never hold SINK while waiting for stdout: the shell holds stdout while a
    // command runs, and a command (`stop x`) prints through here.
    drop(sink);
    let _ = writeln!(std::io::stdout().lock(), "{line}");
}

/// Routes component output to `sink` (the shell's printer); `None` restores stdout.
pub fn set_sink(sink: Option<Sink>) {
    *SINK.lock() = sink;
}

/// `println!` for components: formats and prints one line through [`println()`].
#[macro_export]
macro_rules! jde_println {
    ($($arg:tt)*) => { $crate::output::println(format!($($arg)*)) };
}

/// The log writer (`tracing`): while the interactive shell is editing a line, log
/// lines go through its printer like components' output; otherwise to standard error.
#[derive(Clone, Copy, Default)]
pub struct LogWriter;

/// One log event's text, sent when dropped.
pub struct LogLine(Vec<u8>);

impl<'a> tracing_subscriber::fmt::MakeWriter<'a> for LogWriter {
    type Writer = LogLine;
    fn make_writer(&'a self) -> LogLine {
        LogLine(Vec::new())
    }
}

impl Write for LogLine {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Drop for LogLine {
    fn drop(&mut self) {
        if self.0.is_empty() {
            return;
        }
        let mut sink = SINK.lock();
        if let Some(f) = sink.as_mut() {
            f(String::from_utf8_lossy(&self.0).trim_end().to_string());
            return;
        }
        drop(sink);
        let _ = std::io::stderr().lock().write_all(&self.0);
    }
}

/// What a panic said (its `&str` or `String` payload), for the one-line reports of
/// a schema, a panel or a driver thread that panicked.
pub fn panic_text(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panicked".into())
}
