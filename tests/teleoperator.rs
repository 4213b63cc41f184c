//! teleoperator through the real runtime: the conf's base and pan-tilt commands
//! move the simulated robot and its camera; the name space changes them.
#![cfg(all(feature = "teleoperator", feature = "simulator"))]

use crate::common;

use common::{poll_until, start_conf, world_path};
use std::{sync::Arc, time::Duration};

use jderobot::{
    conf::Conf,
    interfaces::{Encoders, Motors, PtEncoders},
    runtime::Runtime,
};
use parking_lot::Mutex;

fn start(body: &str) -> Arc<Runtime> {
    start_conf(&format!(
        "driver simulator\nworld {}\nrobot robot1 1000 2000 0\nprovides encoders\n\
         provides motors\nprovides laser\nprovides pantiltencoders\nprovides pantiltmotors\n\
         speed 4\nend_driver\nschema teleoperator\n{body}end_schema\n\
         load_driver simulator\nload_schema teleoperator\nrun teleoperator\n",
        world_path("simple.world")
    ))
}

#[test]
fn conf_commands_drive_the_base_and_aim_the_pantilt() {
    let rt = start("base 300 0\npantilt 30 -10\n");
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let pte = rt.interfaces.get::<PtEncoders>("pantiltencoders").unwrap();
    let moved = poll_until(20, || enc.read().value.x > 1500.0);
    let aimed = poll_until(20, || {
        let p = pte.read().value;
        (p.pan_angle - 30.0).abs() < 0.5 && (p.tilt_angle + 10.0).abs() < 0.5
    });
    let e = enc.read().value;
    // Through the name space: stop the base.
    let base = rt
        .names
        .import::<Mutex<Motors>>("teleoperator", "base")
        .expect("exports base");
    *base.lock() = Motors::default();
    let stopped = poll_until(20, || {
        let a = enc.read().value.x;
        std::thread::sleep(Duration::from_millis(300));
        (enc.read().value.x - a).abs() < 1.0
    });
    let pt = rt
        .names
        .import::<Mutex<[f32; 2]>>("teleoperator", "pantilt")
        .expect("exports pantilt");
    *pt.lock() = [-45.0, 20.0];
    let reaimed = poll_until(20, || (pte.read().value.pan_angle + 45.0).abs() < 0.5);
    rt.shutdown();
    assert!(moved, "the robot did not drive ahead: x = {}", e.x);
    assert!(
        (e.y - 2000.0).abs() < 20.0,
        "it drove straight: y = {}",
        e.y
    );
    assert!(aimed, "the pan-tilt did not reach (30, -10)");
    assert!(stopped, "the robot did not stop");
    assert!(reaimed, "the pan-tilt did not follow the name space");
}

#[test]
fn conf_errors_name_file_and_line() {
    for (line, expect) in [
        ("base 1\n", "takes 2 argument"),
        ("max_w 0\n", "between 1 and 180 deg/s"),
        ("motors none\n", "needs a motors interface"),
        ("frobnicate\n", "takes no `frobnicate` line"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("t.conf");
        std::fs::write(
            &file,
            format!(
                "driver simulator\nprovides motors\nend_driver\nschema teleoperator\n{line}\
                 end_schema\nload_driver simulator\nload_schema teleoperator\n"
            ),
        )
        .unwrap();
        let e = match jderobot::loader::start(&Conf::load(&file).unwrap()) {
            Ok(rt) => {
                rt.shutdown();
                panic!("`{line}` accepted")
            }
            Err(e) => e.to_string(),
        };
        assert!(e.contains("t.conf:5"), "{line}: {e}");
        assert!(e.contains(expect), "{line}: {e}");
    }
}
