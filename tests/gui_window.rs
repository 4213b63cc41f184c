//! The real window outlives the end of standard input: a run started from a
//! desktop launcher, with `</dev/null` or under `nohup` keeps its window until it
//! is closed (Ctrl+Q, the Quit button, the window manager) or the process gets
//! SIGINT/SIGTERM.
//!
//! Needs a display (CI runs it under `xvfb-run -a`) and, for the close test,
//! `xdotool`; under `CI` a missing one fails the test.
#![cfg(all(feature = "gui", feature = "introrob", feature = "simulator"))]

use crate::common;

use std::{
    path::PathBuf,
    process::{Child, Command, ExitStatus, Stdio},
    time::Duration,
};

use common::{can_screenshot, poll_until, root};

/// One window at a time: the close test finds its window by name.
static ONE_WINDOW: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Starts `printf '' | jderobot examples/introrob.conf` on the display.
fn start_with_empty_input(log: &str) -> (Child, PathBuf) {
    let log = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(log);
    let child = Command::new(env!("CARGO_BIN_EXE_jderobot"))
        .arg("examples/introrob.conf")
        .current_dir(root())
        .env("LIBGL_ALWAYS_SOFTWARE", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .expect("start jderobot");
    (child, log)
}

fn wait_exit(child: &mut Child, secs: u64) -> Option<ExitStatus> {
    let mut status = None;
    poll_until(secs, || {
        status = child.try_wait().ok().flatten();
        status.is_some()
    });
    status
}

/// The window stays 5 s after standard input ended, then `stop` ends it.
fn stays_open(log: &str, stop: impl FnOnce(&Child)) -> (Option<ExitStatus>, String) {
    let _one = ONE_WINDOW.lock().unwrap_or_else(|e| e.into_inner());
    let (mut child, log) = start_with_empty_input(log);
    std::thread::sleep(Duration::from_secs(5));
    let early = child.try_wait().ok().flatten();
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    if let Some(s) = early {
        panic!("jderobot ended {s} with its window when standard input ended; log:\n{text}");
    }
    assert!(
        text.contains("end of standard input; the window stays open"),
        "log:\n{text}"
    );
    stop(&child);
    let status = wait_exit(&mut child, 20);
    if status.is_none() {
        let _ = child.kill();
        let _ = child.wait();
    }
    (status, std::fs::read_to_string(&log).unwrap_or_default())
}

#[test]
fn end_of_input_keeps_the_window_until_sigterm() {
    let _display = common::x_display();
    if !can_screenshot("gui_window", &[]) {
        return;
    }
    let (status, text) = stays_open("gui_window_sigterm.log", |c| {
        // SAFETY: sends a signal to our own child process.
        unsafe { libc::kill(c.id() as i32, libc::SIGTERM) };
    });
    let status = status.unwrap_or_else(|| panic!("SIGTERM did not end the run; log:\n{text}"));
    assert!(
        status.code().is_some(),
        "ended by a signal, not by its handler: {status}"
    );
}

#[test]
fn end_of_input_keeps_the_window_until_it_is_closed() {
    let _display = common::x_display();
    if !can_screenshot("gui_window", &["xdotool"]) {
        return;
    }
    let (status, text) = stays_open("gui_window_close.log", |_| {
        // The window's own close shortcut (as its Quit button and the window
        // manager's close do).
        let sent = poll_until(20, || {
            Command::new("xdotool")
                .args([
                    "search",
                    "--name",
                    "^jderobot$",
                    "windowfocus",
                    "--sync",
                    "key",
                    "ctrl+q",
                ])
                .status()
                .is_ok_and(|s| s.success())
        });
        assert!(sent, "xdotool found no window named jderobot");
    });
    let status =
        status.unwrap_or_else(|| panic!("closing the window did not end the run; log:\n{text}"));
    assert!(status.success(), "exit status {status}; log:\n{text}");
}
