//! The real window: starts the binary with examples/gui.conf on the X display,
//! takes a screenshot of the root window with imagemagick's `import`, checks that
//! the PNG is not blank, then quits from the shell and expects the window to close
//! and the program to exit 0.
//!
//! Needs a display (CI runs it under `xvfb-run -a`) and imagemagick; without them
//! it says why and passes without checking anything.
#![cfg(all(feature = "gui", feature = "mastergui"))]

use std::{
    io::Write,
    path::PathBuf,
    process::{Command, Stdio},
    time::{Duration, Instant},
};

fn have(cmd: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {cmd}")])
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

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
    if std::env::var_os("DISPLAY").is_none_or(|d| d.is_empty()) {
        eprintln!(
            "skipped: DISPLAY is not set (run under `xvfb-run -a cargo test --test gui_screenshot`)"
        );
        return;
    }
    if !have("import") || !have("identify") {
        eprintln!("skipped: imagemagick's `import`/`identify` are not installed");
        return;
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let png = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("gui_screenshot.png");
    let _ = std::fs::remove_file(&png);
    let log = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("gui_screenshot.log");
    let mut child = Command::new(env!("CARGO_BIN_EXE_jderobot"))
        .arg("examples/gui.conf")
        .current_dir(&root)
        .env("LIBGL_ALWAYS_SOFTWARE", "1")
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).expect("log file"))
        .spawn()
        .expect("start jderobot");

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
    if let Some(stdin) = child.stdin.as_mut() {
        let _ = stdin.write_all(b"ps\nexit\n");
    }
    let t = Instant::now();
    let status = loop {
        if let Ok(Some(s)) = child.try_wait() {
            break Some(s);
        }
        if t.elapsed() > Duration::from_secs(20) {
            let _ = child.kill();
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(
        best >= 16,
        "the screenshot looks blank ({best} colours); log:\n{text}"
    );
    let status =
        status.unwrap_or_else(|| panic!("window did not close after `exit`; log:\n{text}"));
    assert!(status.success(), "exit status {status}; log:\n{text}");
}
