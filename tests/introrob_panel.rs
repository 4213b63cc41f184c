//! introrob's and teleoperator's panels through egui_kittest, headless (no
//! display, no GPU): the behaviour buttons, the world view's click target, STOP,
//! and the teleoperator's pan-tilt pad reach the schemas' shared state.
#![cfg(all(
    feature = "gui",
    feature = "introrob",
    feature = "teleoperator",
    feature = "simulator"
))]

use crate::common;

use common::{panel_harness, start_conf, world_path};
use std::sync::Arc;

use egui::vec2;
use egui_kittest::kittest::Queryable;
use jderobot::{
    runtime::Runtime,
    schemas::introrob::{Behaviour, Dashboard},
};

fn start(schema: &str, body: &str) -> Arc<Runtime> {
    start_conf(&format!(
        "driver simulator\nworld {}\nrobot robot1 1000 1000 90\nprovides encoders\n\
         provides motors\nprovides laser\nprovides sonars\nprovides pantiltencoders\n\
         provides pantiltmotors\nend_driver\nschema {schema}\n{body}end_schema\n\
         load_driver simulator\nload_schema {schema}\n",
        world_path("simple.world")
    ))
}

#[test]
fn introrob_panel_sets_behaviour_target_and_stop() {
    let rt = start("introrob", "behaviour teleop\n");
    let shared = rt.names.import::<Dashboard>("introrob", "state").unwrap();
    let mut h = panel_harness(&rt, "introrob", vec2(1000.0, 700.0));
    h.run();
    h.get_by_label("vff").click();
    h.run();
    assert_eq!(*shared.behaviour.lock(), Behaviour::Vff);
    h.get_by_label("gpp").click();
    h.run();
    assert_eq!(*shared.behaviour.lock(), Behaviour::Gpp);
    // A click in the world view sets the target: the view is centred on the
    // room (6 m x 4 m), so its centre is (3000, 2000).
    assert_eq!(*shared.target.lock(), None);
    h.get_by_label("introrob world").click();
    h.run();
    let t = shared.target.lock().expect("a target was set");
    assert!(
        (t[0] - 3000.0).abs() < 50.0 && (t[1] - 2000.0).abs() < 50.0,
        "{t:?}"
    );
    h.get_by_label("STOP").click();
    h.run();
    assert_eq!(*shared.behaviour.lock(), Behaviour::Stop);
    // The laser and sonar views are there.
    h.get_by_label("introrob laser");
    h.get_by_label("introrob sonars");
    rt.shutdown();
}

#[test]
fn teleoperator_panel_draws_and_stops() {
    let rt = start("teleoperator", "base 200 10\n");
    let mut h = panel_harness(&rt, "teleoperator", vec2(1000.0, 700.0));
    h.run();
    h.get_by_label("teleoperator 3d");
    h.get_by_label("teleoperator pantilt");
    let base = rt
        .names
        .import::<parking_lot::Mutex<jderobot::interfaces::Motors>>("teleoperator", "base")
        .unwrap();
    assert_eq!(base.lock().v, 200.0);
    h.get_by_label("STOP").click();
    h.run();
    assert_eq!(base.lock().v, 0.0);
    rt.shutdown();
}

/// teleoperator's 3D canvas draws a ball as a wireframe sphere resting on the floor.
#[test]
fn balls_are_wireframe_spheres_on_the_floor() {
    use jderobot::{schemas::teleoperator::panel::ball_segments, world::Ball};
    let ball = Ball {
        pos: [4500.0, 1200.0],
        vel: [0.0, 0.0],
        radius: 110.0,
        color: [220, 20, 20],
        friction: 300.0,
    };
    let segs = ball_segments(&[ball]);
    assert_eq!(segs.len(), 48, "three circles of 16 edges");
    for (a, b, c) in &segs {
        assert_eq!(*c, egui::Color32::from_rgb(220, 20, 20));
        for p in [a, b] {
            let d =
                ((p[0] - 4500.0).powi(2) + (p[1] - 1200.0).powi(2) + (p[2] - 110.0).powi(2)).sqrt();
            assert!((d - 110.0).abs() < 1e-9, "{p:?} is on the sphere");
            assert!(p[2] >= -1e-9, "above the floor");
        }
    }
}

/// With a `score` line, the world view says the exercise's score (`world.score`).
#[test]
fn introrob_panel_says_the_exercise_score() {
    let rt = start_conf(&format!(
        "driver simulator\nworld {}\nprovides encoders\nprovides motors\nprovides laser\n\
         score targets\nend_driver\nschema introrob\nbehaviour stop\nend_schema\n\
         load_driver simulator\nload_schema introrob\n",
        world_path("obstacle_circuit.world")
    ));
    let mut h = panel_harness(&rt, "introrob", vec2(1000.0, 700.0));
    h.run();
    h.get_by_label_contains("targets 0 of 8");
    rt.shutdown();
}
