//! introrob's panel in the real window: starts the binary with
//! examples/introrob.conf on the X display, takes screenshots of the root window
//! with imagemagick's `import`, and checks that the world view shows the robot (its
//! red outline) and the laser points (blue dots), and that the robot moves between
//! two screenshots. The last screenshot is kept in
//! target/tmp/introrob_screenshot.png.
//!
//! Needs a display (CI runs it under `xvfb-run -a`) and imagemagick; without them
//! it says why and passes without checking anything.
#![cfg(all(
    feature = "gui",
    feature = "mastergui",
    feature = "introrob",
    feature = "simulator"
))]

use crate::common::{self, can_screenshot, quit, spawn_window};

use std::{
    path::{Path, PathBuf},
    time::{Duration, Instant},
};

/// Pixels within `tol` of `c`: their count and centroid.
fn find(img: &(usize, usize, Vec<[u8; 3]>), c: [u8; 3], tol: i32) -> (usize, [f32; 2]) {
    let (w, _, px) = img;
    let (mut n, mut sx, mut sy) = (0usize, 0f32, 0f32);
    for (k, p) in px.iter().enumerate() {
        if (0..3).all(|i| (p[i] as i32 - c[i] as i32).abs() <= tol) {
            n += 1;
            sx += (k % w) as f32;
            sy += (k / w) as f32;
        }
    }
    let c = if n > 0 {
        [sx / n as f32, sy / n as f32]
    } else {
        [0.0; 2]
    };
    (n, c)
}

/// The robot outline and laser colours of the world view (src/gui/widgets.rs).
const ROBOT: [u8; 3] = [200, 40, 40];
const LASER: [u8; 3] = [30, 90, 220];

fn shoot(png: &Path) -> Option<(usize, usize, Vec<[u8; 3]>)> {
    common::screenshot(png).map(|s| (s.w, s.h, s.px))
}

#[test]
fn introrob_panel_shows_the_robot_and_its_laser_moving() {
    let _display = common::x_display();
    if !can_screenshot("introrob_screenshot", &["import"]) {
        return;
    }
    let tmp = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let png = tmp.join("introrob_screenshot.png");
    let first = tmp.join("introrob_screenshot_first.png");
    let log = tmp.join("introrob_screenshot.log");
    let child = spawn_window("examples/introrob.conf", &log);

    // Wait (software GL is slow to start) until the robot and laser show.
    let start = Instant::now();
    let mut seen = None;
    let mut counts = (0, 0);
    while start.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(1000));
        if let Some(img) = shoot(&first) {
            let (r, c) = find(&img, ROBOT, 10);
            let (l, _) = find(&img, LASER, 10);
            counts = (r, l);
            if r >= 20 && l >= 20 {
                seen = Some(c);
                break;
            }
        }
    }
    // Two seconds later the robot has moved (it drives toward its VFF target).
    let mut moved = None;
    if let Some(c0) = seen {
        std::thread::sleep(Duration::from_secs(2));
        if let Some(img) = shoot(&png) {
            let (r, c1) = find(&img, ROBOT, 10);
            let (l, _) = find(&img, LASER, 10);
            counts = (r, l);
            moved = Some(((c1[0] - c0[0]).powi(2) + (c1[1] - c0[1]).powi(2)).sqrt());
        }
    }
    let status = quit(child, "exit\n");
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    eprintln!(
        "screenshot: {} (robot {} px, laser {} px, robot moved {:?} px)",
        png.display(),
        counts.0,
        counts.1,
        moved
    );
    let c0 = seen.unwrap_or_else(|| {
        panic!(
            "no robot/laser in the screenshot (robot {} px, laser {} px); log:\n{text}",
            counts.0, counts.1
        )
    });
    let _ = c0;
    assert!(
        counts.0 >= 20 && counts.1 >= 20,
        "robot/laser gone: {counts:?}"
    );
    let moved = moved.expect("second screenshot");
    assert!(
        moved > 3.0,
        "the robot did not move in the view ({moved} px)"
    );
    let status = status.unwrap_or_else(|| panic!("did not exit after `exit`; log:\n{text}"));
    assert!(status.success(), "exit status {status}; log:\n{text}");
}
