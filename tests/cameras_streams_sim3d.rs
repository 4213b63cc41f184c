//! simulated3D: the world's lines drawn where progeo projects them.
#![cfg(feature = "simulated3D")]

use crate::common;

use std::sync::Arc;

use common::{eventually, root, start_conf};
use jderobot::{
    Interface,
    drivers::simulated3d::render,
    interfaces::Image,
    progeo::{HPoint3D, PinholeCamera, World},
};

fn asset(name: &str) -> String {
    root()
        .join("assets/simulated3D")
        .join(name)
        .display()
        .to_string()
}

fn dark(img: &Image, col: f64, row: f64) -> bool {
    // Within a pixel of (col, row), a black pixel.
    let (c, r) = (col.round() as i64, row.round() as i64);
    (-1..=1).any(|dc| {
        (-1..=1).any(|dr| {
            let (x, y) = (c + dc, r + dr);
            x >= 0
                && y >= 0
                && (x as u32) < img.width
                && (y as u32) < img.height
                && img.pixel(x as u32, y as u32) == [0, 0, 0]
        })
    })
}

#[test]
fn lines_are_black_on_white_where_progeo_projects_them() {
    let world = World::load(asset("robotics-lab.world")).unwrap();
    for cam in ["cameraA", "cameraB"] {
        let cam = PinholeCamera::load(asset(cam)).unwrap();
        let mut img = Image::default();
        render(&world, &cam, &mut img);
        assert_eq!((img.width, img.height), (cam.columns, cam.rows));
        // SIM3D_DUMP=DIR writes the drawings there, to look at.
        if let Some(dir) = std::env::var_os("SIM3D_DUMP") {
            let p =
                std::path::Path::new(&dir).join(format!("sim3d_{}x{}.ppm", img.width, img.height));
            // Binary PPM (black and white: BGR and RGB are the same).
            let mut ppm = format!("P6\n{} {}\n255\n", img.width, img.height).into_bytes();
            ppm.extend_from_slice(&img.data);
            std::fs::write(p, ppm).unwrap();
        }
        let black = img.data.chunks_exact(3).filter(|p| *p == [0, 0, 0]).count();
        let white = img
            .data
            .chunks_exact(3)
            .filter(|p| *p == [255, 255, 255])
            .count();
        assert_eq!(
            black + white,
            (img.width * img.height) as usize,
            "only black and white"
        );
        assert!(black > 500, "lines drawn: {black} black pixels");
        // The table's top corners (750 mm high) are in view and drawn.
        let mut seen = 0;
        for (x, y) in [
            (3200.0, 2000.0),
            (4800.0, 2000.0),
            (4800.0, 2800.0),
            (3200.0, 2800.0),
        ] {
            let p = cam.project(HPoint3D::point(x, y, 750.0));
            let (c, r) = cam.optical_to_graphic(p);
            if p.h > 0.0
                && c >= 1.0
                && r >= 1.0
                && c < img.width as f64 - 1.0
                && r < img.height as f64 - 1.0
            {
                assert!(
                    dark(&img, c, r),
                    "table corner ({x}, {y}) at ({c:.1}, {r:.1}) not drawn"
                );
                seen += 1;
            }
        }
        assert!(seen >= 3, "the table is in view");
    }
}

/// Through the runtime: nothing is rendered until the interface is used, then
/// each frame is the same drawing and the clock moves once per frame.
#[test]
fn the_driver_renders_only_while_used() {
    let rt = start_conf(&format!(
        "driver simulated3D\nworldfile {}\nprovides colorA {}\nprovides varcolorB {}\nend_driver\nload_driver simulated3D\n",
        asset("robotics-lab.world"),
        asset("cameraA"),
        asset("cameraB")
    ));
    let a: Arc<Interface<Image>> = rt.interfaces.get("colorA").unwrap();
    let b: Arc<Interface<Image>> = rt.interfaces.get("varcolorB").unwrap();
    std::thread::sleep(std::time::Duration::from_millis(200));
    assert_eq!((a.clock(), b.clock()), (0, 0), "nobody uses them yet");
    rt.run("varcolorB").unwrap();
    eventually("frames on varcolorB", || b.clock() >= 3);
    assert_eq!(a.clock(), 0, "colorA is not used: not rendered");
    let world = World::load(asset("robotics-lab.world")).unwrap();
    let mut want = Image::default();
    render(
        &world,
        &PinholeCamera::load(asset("cameraB")).unwrap(),
        &mut want,
    );
    assert!(b.read().value == want, "the published frame is the drawing");
    rt.stop("varcolorB").unwrap();
    std::thread::sleep(std::time::Duration::from_millis(100));
    let c = b.clock();
    std::thread::sleep(std::time::Duration::from_millis(300));
    assert_eq!(b.clock(), c, "no frames once stopped");
    rt.shutdown();
}

#[test]
fn conf_errors_name_the_line() {
    let bad = |body: &str| -> String {
        let conf = jderobot::Conf::parse(
            &format!("driver simulated3D\n{body}\nend_driver\nload_driver simulated3D\n"),
            std::path::Path::new("t.conf"),
        )
        .unwrap();
        match jderobot::loader::start(&conf) {
            Ok(_) => panic!("{body}: expected an error"),
            Err(e) => e.to_string(),
        }
    };
    let e = bad(&format!(
        "worldfile {}\nprovides colorA {}",
        asset("robotics-lab.world"),
        asset("cameraB")
    ));
    assert!(
        e.contains("t.conf:3") && e.contains("640x480") && e.contains("varcolor"),
        "{e}"
    );
    let e = bad(&format!("provides colorA {}", asset("cameraA")));
    assert!(e.contains("no `worldfile` line"), "{e}");
    let e = bad("worldfile /nonexistent/world\nprovides colorA x");
    assert!(
        e.contains("t.conf:2") && e.contains("/nonexistent/world"),
        "{e}"
    );
    let e = bad(&format!(
        "worldfile {}\nprovides laser {}",
        asset("robotics-lab.world"),
        asset("cameraA")
    ));
    assert!(e.contains("not `laser`"), "{e}");
}
