//! opengldemo's and opengl_viewer's panels in the real window, drawn with real
//! OpenGL (under Xvfb: Mesa's llvmpipe). Each test starts the binary with a conf
//! it writes, takes screenshots of the root window with imagemagick's `import`,
//! and checks:
//!
//! - opengldemo: the view is where the sky-coloured background is; projecting
//!   points of the simple world's walls with progeo (the conf's camera, through the
//!   manual's OpenGL → progeo mapping, for the view's size in pixels) lands on
//!   wall-coloured pixels, and a point of the floor on floor-coloured ones; with
//!   `rotate on` the view changes between two screenshots;
//! - opengl_viewer: the robot model's red body shows, with its blue laser fan, and
//!   it moves on screen while introrob drives the robot (the encoders change).
//!
//! The last screenshots are kept in target/tmp/opengl_*.png. Needs a display (CI
//! runs it under `xvfb-run -a`) and imagemagick; without them it says why and
//! passes without checking anything (under `CI` it fails).
#![cfg(all(
    feature = "gui",
    feature = "opengldemo",
    feature = "opengl_viewer",
    feature = "simulator",
    feature = "introrob"
))]

use crate::common;

use std::{
    path::{Path, PathBuf},
    time::{Duration, Instant},
};

use common::{Shot, can_screenshot, quit, root, screenshot, spawn_window};
use jderobot::progeo::{GlCamera, HPoint3D};

/// simple.world's colours (src/world/parse.rs): sky, beige walls, floor.
const SKY: [u8; 3] = [170, 200, 235];
const WALL: [u8; 3] = [225, 215, 185];
const FLOOR: [u8; 3] = [150, 150, 140];

fn near(a: [u8; 3], b: [u8; 3], tol: i32) -> bool {
    (0..3).all(|i| (a[i] as i32 - b[i] as i32).abs() <= tol)
}

/// The bounding box (x0, y0, x1, y1, inclusive) of the pixels near `c`.
fn bbox(s: &Shot, c: [u8; 3]) -> Option<(usize, usize, usize, usize)> {
    let mut b: Option<(usize, usize, usize, usize)> = None;
    for y in 0..s.h {
        for x in 0..s.w {
            if near(s.at(x, y), c, 2) {
                b = Some(match b {
                    None => (x, y, x, y),
                    Some((x0, y0, x1, y1)) => (x0.min(x), y0.min(y), x1.max(x), y1.max(y)),
                });
            }
        }
    }
    b
}

fn tmp(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name)
}

/// The test camera: south-west of the room, above, looking at its middle.
const CAM: [f64; 6] = [-9000.0, -11000.0, 9000.0, 3000.0, 2000.0, 0.0];
const FOVY: f64 = 40.0;

fn demo_conf(rotate: bool) -> String {
    let world = root().join("assets/worlds/simple.world");
    format!(
        "driver simulator\nworld {}\nrobot robot1 1000 1000 90\nprovides encoders\n\
         provides motors\nend_driver\n\
         schema opengldemo\ncamera {}\nfovy {FOVY}\nrotate {}\nrotate_speed 40\nend_schema\n\
         load_driver simulator\nload_service gui\nload_schema opengldemo\n\
         run opengldemo\nshow opengldemo\n",
        world.display(),
        CAM.map(|v| v.to_string()).join(" "),
        if rotate { "on" } else { "off" },
    )
}

/// Waits up to 60 s (software GL is slow to start) for a screenshot with the sky
/// colour in a region at least 200x150.
fn wait_for_view(
    png: &Path,
    child: &mut std::process::Child,
    log: &Path,
) -> Option<(Shot, (usize, usize, usize, usize))> {
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(1000));
        if let Ok(Some(status)) = child.try_wait() {
            let text = std::fs::read_to_string(log).unwrap_or_default();
            panic!("jderobot exited early ({status}):\n{text}");
        }
        if let Some(s) = screenshot(png)
            && let Some(b) = bbox(&s, SKY)
            && b.2 - b.0 >= 200
            && b.3 - b.1 >= 150
        {
            return Some((s, b));
        }
    }
    None
}

#[test]
fn opengldemo_draws_the_world_where_progeo_projects_it() {
    if !can_screenshot("opengl_screenshot", &["import"]) {
        return;
    }
    let _screen = common::x_display();
    let conf = tmp("opengl_demo.conf");
    std::fs::write(&conf, demo_conf(false)).unwrap();
    let png = tmp("opengl_demo.png");
    let log = tmp("opengl_demo.log");
    let mut child = spawn_window(conf.to_str().unwrap(), &log);
    let seen = wait_for_view(&png, &mut child, &log);
    let status = quit(child, "exit\n");
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    let (shot, (x0, y0, x1, y1)) =
        seen.unwrap_or_else(|| panic!("no 3D view (sky colour) on the screen; log:\n{text}"));
    let (w, h) = ((x1 - x0 + 1) as u32, (y1 - y0 + 1) as u32);
    eprintln!(
        "view at ({x0}, {y0}), {w}x{h} px; screenshot {}",
        png.display()
    );
    // The conf's OpenGL camera as a progeo camera for this view.
    let gl = GlCamera {
        position: [CAM[0], CAM[1], CAM[2]],
        foa: [CAM[3], CAM[4], CAM[5]],
        roll: 0.0,
        fovy: FOVY.to_radians(),
        aspect: w as f64 / h as f64,
        near: 50.0,
        far: 2.0e5,
    };
    let cam = gl.to_progeo(w, h);
    let check = |p: [f64; 3], want: [u8; 3], what: &str| {
        let q = cam.project(HPoint3D::point(p[0], p[1], p[2]));
        assert_eq!(q.h, 1.0, "{what} is behind the camera");
        let (c, r) = cam.optical_to_graphic(q);
        let (sx, sy) = (x0 as f64 + c.round(), y0 as f64 + r.round());
        assert!(
            sx >= x0 as f64 && sx <= x1 as f64 && sy >= y0 as f64 && sy <= y1 as f64,
            "{what} {p:?} projects outside the view: ({sx}, {sy})"
        );
        let (sx, sy) = (sx as usize, sy as usize);
        // The pixel and most of its 3x3 neighbourhood have the colour.
        let mut hits = 0;
        for dy in 0..3 {
            for dx in 0..3 {
                hits += near(shot.at(sx + dx - 1, sy + dy - 1), want, 6) as usize;
            }
        }
        assert!(
            near(shot.at(sx, sy), want, 6) && hits >= 6,
            "{what} {p:?}: pixel ({sx}, {sy}) is {:?} ({hits}/9 near {want:?}), screenshot {}",
            shot.at(sx, sy),
            png.display()
        );
    };
    // The outer faces of the south and west walls (1 m high), seen from the
    // south-west; a floor point in the middle of a grid cell inside the room.
    check([1500.0, 0.0, 500.0], WALL, "the south wall");
    check([4500.0, 0.0, 400.0], WALL, "the south wall, east part");
    check([0.0, 2500.0, 500.0], WALL, "the west wall");
    check([1500.0, 2500.0, 0.0], FLOOR, "the floor");
    let status = status.unwrap_or_else(|| panic!("did not exit after `exit`; log:\n{text}"));
    assert!(status.success(), "exit status {status}; log:\n{text}");
}

/// Pixels that differ between two screenshots inside a box.
fn differing(a: &Shot, b: &Shot, bx: (usize, usize, usize, usize)) -> usize {
    let mut n = 0;
    for y in bx.1..=bx.3 {
        for x in bx.0..=bx.2 {
            n += !near(a.at(x, y), b.at(x, y), 4) as usize;
        }
    }
    n
}

#[test]
fn opengldemo_rotate_changes_the_picture() {
    if !can_screenshot("opengl_screenshot", &["import"]) {
        return;
    }
    let _screen = common::x_display();
    let conf = tmp("opengl_rotate.conf");
    std::fs::write(&conf, demo_conf(true)).unwrap();
    let (png1, png2) = (tmp("opengl_rotate_1.png"), tmp("opengl_rotate_2.png"));
    let log = tmp("opengl_rotate.log");
    let mut child = spawn_window(conf.to_str().unwrap(), &log);
    let first = wait_for_view(&png1, &mut child, &log);
    std::thread::sleep(Duration::from_millis(1500));
    let second = screenshot(&png2);
    let status = quit(child, "exit\n");
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    let (a, bx) = first.unwrap_or_else(|| panic!("no 3D view on the screen; log:\n{text}"));
    let b = second.expect("second screenshot");
    let n = differing(&a, &b, bx);
    eprintln!("{n} pixels of the view changed in 1.5 s");
    assert!(
        n > 2000,
        "rotate on, but the view hardly changed ({n} pixels); {} {}",
        png1.display(),
        png2.display()
    );
    let status = status.unwrap_or_else(|| panic!("did not exit after `exit`; log:\n{text}"));
    assert!(status.success(), "exit status {status}; log:\n{text}");
}

/// The red body of the built-in Pioneer (pioneer.mtl's `pioneer_red`, shaded
/// 0.65..1.0) and the laser fan's blue.
fn is_body(p: [u8; 3]) -> bool {
    p[0] >= 120 && p[1] <= 40 && p[2] <= 40
}
const LASER: [u8; 3] = [30, 90, 220];

fn body(s: &Shot) -> (usize, [f32; 2]) {
    let (mut n, mut sx, mut sy) = (0usize, 0f32, 0f32);
    for y in 0..s.h {
        for x in 0..s.w {
            if is_body(s.at(x, y)) {
                n += 1;
                sx += x as f32;
                sy += y as f32;
            }
        }
    }
    (
        n,
        if n > 0 {
            [sx / n as f32, sy / n as f32]
        } else {
            [0.0; 2]
        },
    )
}

#[test]
fn opengl_viewer_shows_the_robot_moving_with_its_encoders() {
    if !can_screenshot("opengl_screenshot", &["import"]) {
        return;
    }
    let _screen = common::x_display();
    // simple.world's room and partition without its red ball (red like the body).
    let world = tmp("opengl_viewer.world");
    std::fs::write(
        &world,
        "wall_height 1000\nwall_color beige\nroom 0 0 6000 4000\nwall 3000 0 3000 1500\n",
    )
    .unwrap();
    let conf = format!(
        "driver simulator\nworld {}\nrobot robot1 1000 1000 0\nprovides encoders\n\
         provides motors\nprovides laser 180 1\nprovides sonars\nprovides pantiltencoders\n\
         end_driver\n\
         schema introrob\nbehaviour vff\ntarget 5000 1000\nmax_v 500\nend_schema\n\
         schema opengl_viewer\ncamera 3000 -4000 5000 3000 1500 0\nfollow off\nend_schema\n\
         load_driver simulator\nload_service gui\nload_schema introrob\n\
         load_schema opengl_viewer\nrun introrob\nrun opengl_viewer\nshow opengl_viewer\n",
        world.display()
    );
    let path = tmp("opengl_viewer.conf");
    std::fs::write(&path, conf).unwrap();
    let (png1, png2) = (tmp("opengl_viewer_1.png"), tmp("opengl_viewer_2.png"));
    let log = tmp("opengl_viewer.log");
    let mut child = spawn_window(path.to_str().unwrap(), &log);
    let first = wait_for_view(&png1, &mut child, &log);
    let mut laser = 0;
    let mut before = None;
    if let Some((s, _)) = &first {
        before = Some(body(s));
        laser = s.px.iter().filter(|p| near(**p, LASER, 8)).count();
    }
    std::thread::sleep(Duration::from_secs(2));
    let after = screenshot(&png2).map(|s| body(&s));
    let status = quit(child, "exit\n");
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    let (n0, c0) = before.unwrap_or_else(|| panic!("no 3D view on the screen; log:\n{text}"));
    let (n1, c1) = after.expect("second screenshot");
    let moved = ((c1[0] - c0[0]).powi(2) + (c1[1] - c0[1]).powi(2)).sqrt();
    eprintln!(
        "robot body {n0} then {n1} px, moved {moved:.1} px; laser {laser} px; {} {}",
        png1.display(),
        png2.display()
    );
    assert!(
        n0 >= 100 && n1 >= 100,
        "no robot model: {n0}, {n1} red pixels"
    );
    assert!(laser >= 50, "no laser fan: {laser} blue pixels");
    assert!(moved > 3.0, "the robot did not move on screen ({moved} px)");
    let status = status.unwrap_or_else(|| panic!("did not exit after `exit`; log:\n{text}"));
    assert!(status.success(), "exit status {status}; log:\n{text}");
}
