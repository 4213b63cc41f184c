//! The real window: starts the binary with examples/gui.conf on the X display,
//! takes a screenshot of the root window with imagemagick's `import`, checks that
//! the PNG is not blank, then quits from the shell and expects the window to close
//! and the program to exit 0.
//!
//! Needs a display (CI runs it under `xvfb-run -a`) and imagemagick; without them
//! it says why and passes without checking anything.
#![cfg(all(feature = "gui", feature = "mastergui"))]

use crate::common;

use std::{
    path::PathBuf,
    process::Command,
    time::{Duration, Instant},
};

use common::{can_screenshot, quit, spawn_window};

/// Number of distinct colours in a PNG (imagemagick's `%k`).
fn colours(png: &PathBuf) -> Option<u64> {
    let out = Command::new("identify")
        .args(["-format", "%k"])
        .arg(png)
        .output()
        .ok()?;
    String::from_utf8_lossy(&out.stdout).trim().parse().ok()
}

#[test]
fn window_renders_under_x_and_quits_with_the_shell() {
    let _display = common::x_display();
    if !can_screenshot("gui_screenshot", &["import", "identify"]) {
        return;
    }
    let png = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("gui_screenshot.png");
    let _ = std::fs::remove_file(&png);
    let log = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("gui_screenshot.log");
    let mut child = spawn_window("examples/gui.conf", &log);

    // The window takes a moment (software GL): retry until the screen has content.
    let start = Instant::now();
    let mut best = 0;
    while start.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(1500));
        if let Ok(Some(status)) = child.try_wait() {
            let text = std::fs::read_to_string(&log).unwrap_or_default();
            panic!("jderobot exited early ({status}):\n{text}");
        }
        let ok = Command::new("import")
            .args(["-window", "root"])
            .arg(&png)
            .status()
            .is_ok_and(|s| s.success());
        if ok {
            best = colours(&png).unwrap_or(0);
            // A rendered egui window has text, widgets and anti-aliasing: many colours.
            if best >= 16 {
                break;
            }
        }
    }
    eprintln!("screenshot: {} ({best} distinct colours)", png.display());

    // Quitting the shell closes the window and the program exits 0.
    let status = quit(child, "ps\nexit\n");
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(
        best >= 16,
        "the screenshot looks blank ({best} colours); log:\n{text}"
    );
    let status =
        status.unwrap_or_else(|| panic!("window did not close after `exit`; log:\n{text}"));
    assert!(status.success(), "exit status {status}; log:\n{text}");
}
