//! naooperator through the real runtime against the simulator (a stand-in for a
//! walking robot: NAOqi is out of reach): the conf's walk and head commands move
//! the robot and its head, the name space changes them, stopping stops the walk;
//! its panel shows the joystick, the head positioner and the camera.
#![cfg(all(feature = "naooperator", feature = "simulator"))]

use crate::common;

use common::{eventually, start_conf};
use std::time::Duration;

use jderobot::interfaces::{Encoders, Motors, PtEncoders};
use parking_lot::Mutex;

fn conf(body: &str) -> String {
    format!(
        "driver simulator\nrobot robot1 0 0 0\nprovides encoders\nprovides motors\n\
         provides pantiltencoders\nprovides pantiltmotors\nprovides varcolorA 320 240\nend_driver\n\
         schema naooperator\n{body}end_schema\n\
         load_driver simulator\nload_schema naooperator\nrun naooperator\n"
    )
}

#[test]
fn walks_turns_the_head_and_stops() {
    let rt = start_conf(&conf("walk 200 0\nhead 30 -10\n"));
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let pte = rt.interfaces.get::<PtEncoders>("pantiltencoders").unwrap();
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    eventually("walks ahead", || enc.read().x > 300.0);
    eventually("head at (30, -10)", || {
        let p = pte.read().value;
        (p.pan_angle - 30.0).abs() < 0.5 && (p.tilt_angle + 10.0).abs() < 0.5
    });
    let head = rt
        .names
        .import::<Mutex<[f32; 2]>>("naooperator", "head")
        .expect("exports head");
    *head.lock() = [-40.0, 5.0];
    eventually("head follows the name space", || {
        (pte.read().pan_angle + 40.0).abs() < 0.5
    });
    let walk = rt
        .names
        .import::<Mutex<Motors>>("naooperator", "walk")
        .expect("exports walk");
    *walk.lock() = Motors { v: 0.0, w: 20.0 };
    eventually("turns in place", || motors.read().w == 20.0);
    rt.stop("naooperator").unwrap();
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(
        motors.read().value,
        Motors::default(),
        "stopping stops the walk"
    );
    rt.shutdown();
}

#[cfg(feature = "gui")]
#[test]
fn panel_has_joystick_head_and_camera() {
    use egui_kittest::kittest::Queryable;
    let rt = start_conf(&conf(""));
    let cam = rt
        .interfaces
        .get::<jderobot::interfaces::Image>("varcolorA")
        .unwrap();
    eventually("a camera frame", || cam.clock() > 0);
    let mut h = common::panel_harness(&rt, "naooperator", egui::vec2(700.0, 420.0));
    h.run();
    for label in ["walk", "head", "camera", "STOP"] {
        assert!(
            h.query_by_label(label).is_some(),
            "no `{label}` in the panel"
        );
    }
    rt.shutdown();
}

#[test]
fn needs_motors_and_names_the_line() {
    for (body, expect) in [
        ("motors none\n", "needs a motors interface"),
        ("walk 1\n", "test.conf:"),
        ("max_v 0\n", "max_v"),
        ("dance\n", "takes no `dance` line"),
    ] {
        let err = common::start_error(&conf(body));
        assert!(err.contains(expect), "{body}: {err}");
    }
}
