//! opengldemo and opengl_viewer without a display: their conf lines and errors,
//! the orbit the schema steps headless, and their panels' controls in an
//! egui_kittest harness (the OpenGL drawing itself is checked under Xvfb by
//! tests/opengl_screenshot.rs).
#![cfg(all(
    feature = "opengldemo",
    feature = "opengl_viewer",
    feature = "simulator"
))]

use crate::common;

use std::time::Duration;

use common::{assert_help_names, eventually, panel_harness, start_conf, start_error, world_path};
use egui_kittest::kittest::Queryable;
use jderobot::schemas::opengldemo::DemoView;
use parking_lot::Mutex;

#[test]
fn help_names_every_line() {
    assert_help_names(
        "opengldemo",
        &["camera", "fovy", "rotate", "rotate_speed", "world", "cycle"],
    );
    assert_help_names(
        "opengl_viewer",
        &[
            "model",
            "model_scale",
            "camera",
            "follow",
            "fovy",
            "robot_camera",
            "frustum",
            "world",
            "encoders",
            "laser",
            "sonars",
            "pantiltencoders",
            "cycle",
        ],
    );
}

#[test]
fn a_bad_model_names_the_conf_line_and_the_obj_line() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("robot.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n").unwrap();
    let e = start_error(&format!(
        "schema opengl_viewer\nmodel {}\nend_schema\nload_schema opengl_viewer\n",
        obj.display()
    ));
    assert!(
        e.contains("test.conf:2") && e.contains("robot.obj:5:"),
        "{e}"
    );
    let e = start_error(
        "schema opengl_viewer\nmodel /nonexistent/robot.obj\nend_schema\nload_schema opengl_viewer\n",
    );
    assert!(e.contains("test.conf:2") && e.contains("robot.obj"), "{e}");
}

#[test]
fn a_camera_looking_nowhere_is_refused_at_its_line() {
    let e = start_error(
        "schema opengldemo\nfovy 50\ncamera 1 2 3 1 2 3\nend_schema\nload_schema opengldemo\n",
    );
    assert!(
        e.contains("test.conf:3") && e.contains("focus of attention"),
        "{e}"
    );
    let e = start_error("schema opengldemo\nrotate maybe\nend_schema\nload_schema opengldemo\n");
    assert!(e.contains("test.conf:2") && e.contains("on or off"), "{e}");
}

#[test]
fn rotate_orbits_the_camera_about_its_focus_headless() {
    let rt = start_conf(&format!(
        "driver simulator\nworld {}\nprovides encoders\nend_driver\n\
         schema opengldemo\ncamera 8000 0 3000 0 0 0\nrotate on\nrotate_speed 90\ncycle 20\n\
         end_schema\nload_driver simulator\nload_schema opengldemo\nrun opengldemo\n",
        world_path("simple.world")
    ));
    let view = rt
        .names
        .import::<Mutex<DemoView>>("opengldemo", "view")
        .unwrap();
    let start = view.lock().camera;
    eventually("the camera orbits", || {
        let c = view.lock().camera;
        let moved = (c.position[1] - start.position[1]).abs() > 1000.0;
        // Same focus, same distance and height.
        let r = (c.position[0].powi(2) + c.position[1].powi(2)).sqrt();
        assert!((r - 8000.0).abs() < 1.0 && (c.position[2] - 3000.0).abs() < 1.0);
        assert_eq!(c.foa, [0.0, 0.0, 0.0]);
        moved
    });
    rt.shutdown();
}

#[test]
fn the_panel_toggles_rotate_and_moves_the_camera() {
    let rt = start_conf(
        "schema opengldemo\nworld none\nrotate off\nend_schema\nload_schema opengldemo\n",
    );
    let view = rt
        .names
        .import::<Mutex<DemoView>>("opengldemo", "view")
        .unwrap();
    let before = *view.lock();
    assert!(!before.rotate);
    let mut h = panel_harness(&rt, "opengldemo", egui::vec2(700.0, 800.0));
    h.run();
    h.get_by_label("rotate").click();
    h.run();
    assert!(view.lock().rotate, "the rotate toggle reaches the schema");
    // Dragging in the view orbits the camera about its focus.
    let canvas = h.get_by_label("opengldemo view").rect();
    let (a, b) = (canvas.center(), canvas.center() + egui::vec2(60.0, 20.0));
    h.hover_at(a);
    h.run();
    h.drag_at(a);
    h.run();
    h.hover_at(b);
    h.run();
    h.drop_at(b);
    h.run();
    let after = view.lock().camera;
    assert_ne!(after.position, before.camera.position, "the drag orbits");
    assert_eq!(after.foa, before.camera.foa);
    std::thread::sleep(Duration::from_millis(10));
    rt.shutdown();
}

#[test]
fn the_viewer_panel_draws_without_a_gpu() {
    let rt = start_conf(&format!(
        "driver simulator\nworld {}\nrobot robot1 1000 1000 0\nprovides encoders\nprovides motors\n\
         provides laser 180 1\nprovides sonars\nend_driver\n\
         schema opengl_viewer\nend_schema\nload_driver simulator\nload_schema opengl_viewer\n\
         run opengl_viewer\n",
        world_path("simple.world")
    ));
    let mut h = panel_harness(&rt, "opengl_viewer", egui::vec2(700.0, 700.0));
    h.run();
    assert!(h.query_by_label("opengl_viewer view").is_some());
    assert!(h.query_by_label("follow the robot").is_some());
    rt.shutdown();
}
