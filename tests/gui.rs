//! The GUI through egui_kittest, headless (no display, no GPU): mastergui's toggles
//! change the runtime's state, and each widget's interaction gives the right values.
#![cfg(all(feature = "gui", feature = "mastergui", feature = "myschema"))]

use crate::common;

use common::{eventually, panel_harness, state};
use std::{path::Path, sync::Arc};

use egui::{Pos2, Rect, pos2, vec2};
use egui_kittest::{Harness, kittest::Queryable};
use jderobot::{
    ComponentConf, Kind, Runtime, State,
    gui::GuiHost,
    interfaces::{Encoders, Image, Laser},
    registry,
    widgets::{
        ImageView, Joystick, OrbitCamera, PanTiltLimits, PanTiltPad, PixelPick, Wireframe3D,
        WorldScene, WorldView,
    },
};

fn runtime_with(names: &[(&str, Kind)]) -> Arc<Runtime> {
    let path = Path::new("jde.conf");
    let rt = Runtime::new(path);
    for (name, kind) in names {
        let comp = registry::find(name).unwrap_or_else(|| panic!("{name} compiled in"));
        jderobot::loader::load_entry(&rt, comp, &ComponentConf::empty(*kind, name, path))
            .unwrap_or_else(|e| panic!("load {name}: {e}"));
    }
    rt
}

/// Presses and releases the primary button at `pos`, running frames in between.
fn click_at<S>(h: &mut Harness<'_, S>, pos: Pos2) {
    h.hover_at(pos);
    h.run();
    h.drag_at(pos);
    h.run();
    h.drop_at(pos);
    h.run();
}

#[test]
fn mastergui_run_stop_toggles_schema_state() {
    let rt = runtime_with(&[("mastergui", Kind::Schema), ("myschema", Kind::Schema)]);
    let mut h = panel_harness(&rt, "mastergui", vec2(700.0, 700.0));
    h.run();
    assert_eq!(state(&rt, "myschema"), State::Slept);

    h.get_by_label("run myschema").click();
    h.run();
    assert_ne!(
        state(&rt, "myschema"),
        State::Slept,
        "run toggle runs the schema"
    );
    eventually("myschema to iterate", || {
        state(&rt, "myschema") == State::Winner
    });

    h.run();
    h.get_by_label("run myschema").click();
    h.run();
    assert_eq!(
        state(&rt, "myschema"),
        State::Slept,
        "run toggle stops the schema"
    );
    rt.shutdown();
}

#[test]
fn mastergui_show_hide_toggles_the_shared_shown_state() {
    let rt = runtime_with(&[("mastergui", Kind::Schema), ("myschema", Kind::Schema)]);
    let mut h = panel_harness(&rt, "mastergui", vec2(700.0, 700.0));
    h.run();
    let shown = |rt: &Runtime| rt.schema("myschema").expect("loaded").shown();
    assert!(!shown(&rt));
    h.get_by_label("show myschema").click();
    h.run();
    assert!(shown(&rt), "show toggle shows the panel");
    h.get_by_label("show myschema").click();
    h.run();
    assert!(!shown(&rt), "show toggle hides the panel");

    // The shell's and the conf's show act on the same state: the checkbox follows.
    // (The checkbox follows: a click now hides it again.)
    rt.show("myschema").expect("show");
    h.run();
    h.get_by_label("show myschema").click();
    h.run();
    assert!(!shown(&rt), "the checkbox followed the shell's show");
    rt.shutdown();
}

#[test]
fn mastergui_lists_drivers_services_and_their_interfaces() {
    let rt = runtime_with(&[("gui", Kind::Service), ("mastergui", Kind::Schema)]);
    let laser = rt
        .interfaces
        .provide::<Laser>("laser", "gui")
        .expect("provide laser");
    laser
        .publish(Laser {
            readings: vec![1000; 180],
            resolution: 1.0,
            ..Laser::default()
        })
        .expect("publish");
    laser.resume();
    let mut h = panel_harness(&rt, "mastergui", vec2(700.0, 700.0));
    h.run();
    h.get_by_label("gui (service)");
    assert!(h.query_all_by_label("laser").count() >= 1);
    h.get_by_label("mastergui");
    // clock 1 and 1 user appear in the laser's row (several cells may read "1").
    assert!(h.query_all_by_label("1").count() >= 2);
    rt.shutdown();
}

/// The whole window's contents (the GUI host) in a harness.
fn host_harness(rt: &Arc<Runtime>) -> Harness<'static> {
    let mut host = GuiHost::new(rt.clone());
    Harness::builder()
        .with_size(vec2(1100.0, 700.0))
        .build_ui(move |ui| host.ui(ui))
}

#[test]
fn host_docks_mastergui_and_its_toggles_drive_the_runtime() {
    let rt = runtime_with(&[
        ("gui", Kind::Service),
        ("mastergui", Kind::Schema),
        ("myschema", Kind::Schema),
    ]);
    rt.show("mastergui").expect("show");
    let mut h = host_harness(&rt);
    h.run();
    h.get_by_label("run myschema").click();
    h.run();
    assert_ne!(state(&rt, "myschema"), State::Slept);
    h.get_by_label("show myschema").click();
    h.run();
    assert!(rt.schema("myschema").expect("loaded").shown());
    // myschema has no panel: the host says so in its window.
    h.run();
    h.get_by_label("schema `myschema` has no panel");
    rt.shutdown();
}

/// A panel that panics is replaced by a note; the window and the schemas go on.
#[test]
fn a_panel_that_panics_is_replaced_by_a_note() {
    struct Faulty;
    impl jderobot::Schema for Faulty {
        fn cycle(&self) -> std::time::Duration {
            std::time::Duration::from_millis(20)
        }
        fn iteration(&mut self, _: &jderobot::Context) -> anyhow::Result<()> {
            Ok(())
        }
        fn panel(&mut self) -> Option<Box<dyn jderobot::runtime::Panel>> {
            struct Boom;
            impl jderobot::runtime::Panel for Boom {
                fn ui(&mut self, _: &mut egui::Ui, _: &Runtime) {
                    panic!("boom in the panel");
                }
            }
            Some(Box::new(Boom))
        }
    }
    let rt = runtime_with(&[("gui", Kind::Service), ("mastergui", Kind::Schema)]);
    rt.add_schema("faulty", "a schema whose panel panics", Box::new(Faulty))
        .expect("add");
    rt.run("faulty").expect("run");
    rt.show("mastergui").expect("show");
    rt.show("faulty").expect("show");
    let mut h = host_harness(&rt);
    h.run();
    h.run();
    h.get_by_label("this panel failed: boom in the panel");
    // mastergui still draws and still drives the runtime.
    h.get_by_label("run faulty").click();
    h.run();
    assert_eq!(state(&rt, "faulty"), State::Slept);
    rt.shutdown();
}

fn test_image() -> Image {
    // 4x2: row 0 = red, green, blue, white; row 1 = black, grey, (1,2,3), yellow.
    let px: [[u8; 3]; 8] = [
        [0, 0, 255],
        [0, 255, 0],
        [255, 0, 0],
        [255, 255, 255],
        [0, 0, 0],
        [128, 128, 128],
        [3, 2, 1],
        [0, 255, 255],
    ];
    Image {
        width: 4,
        height: 2,
        data: px.iter().flatten().copied().collect(),
    }
}

#[test]
fn image_view_click_gives_pixel_coordinates_and_colour() {
    struct S {
        view: ImageView,
        image: Image,
        picks: Vec<PixelPick>,
    }
    let state = S {
        view: ImageView::new("camera"),
        image: test_image(),
        picks: Vec::new(),
    };
    let mut h = Harness::builder()
        .with_size(vec2(400.0, 300.0))
        .build_ui_state(
            |ui, s: &mut S| {
                let r = s.view.show(ui, &s.image, 1);
                if let Some(p) = r.pick {
                    s.picks.push(p);
                }
            },
            state,
        );
    h.run();
    let rect = h.get_by_label("camera").rect();
    // Scaled to fit: 4x2 keeps its 2:1 aspect ratio.
    assert!(
        (rect.width() / rect.height() - 2.0).abs() < 0.05,
        "{rect:?}"
    );
    let cell = vec2(rect.width() / 4.0, rect.height() / 2.0);
    let at = |x: f32, y: f32| rect.min + vec2((x + 0.5) * cell.x, (y + 0.5) * cell.y);
    click_at(&mut h, at(2.0, 1.0));
    click_at(&mut h, at(1.0, 0.0));
    let picks = &h.state().picks;
    assert_eq!(
        picks,
        &vec![
            PixelPick {
                x: 2,
                y: 1,
                bgr: [3, 2, 1]
            },
            PixelPick {
                x: 1,
                y: 0,
                bgr: [0, 255, 0]
            }
        ]
    );
    // One upload for one clock, however many frames were drawn.
    assert_eq!(h.state().view.uploads(), 1);
}

#[test]
fn image_view_reuploads_only_when_the_clock_changes() {
    struct S {
        view: ImageView,
        image: Image,
        clock: u64,
    }
    let mut h = Harness::builder()
        .with_size(vec2(400.0, 300.0))
        .build_ui_state(
            |ui, s: &mut S| {
                s.view.show(ui, &s.image, s.clock);
            },
            S {
                view: ImageView::new("camera"),
                image: test_image(),
                clock: 1,
            },
        );
    h.run();
    h.run();
    assert_eq!(h.state().view.uploads(), 1);
    h.state_mut().clock = 2;
    h.run();
    assert_eq!(h.state().view.uploads(), 2);
    // A 640x480 image of another size works too.
    h.state_mut().image = Image::new(640, 480);
    h.run();
    assert_eq!(h.state().view.uploads(), 3);
}

#[test]
fn joystick_drag_gives_v_and_w_and_release_stops() {
    let mut h = Harness::builder()
        .with_size(vec2(300.0, 300.0))
        .build_ui_state(
            |ui, j: &mut Joystick| {
                j.show(ui, 200.0);
            },
            Joystick::new("joystick", 500.0, 30.0),
        );
    h.run();
    let rect = h.get_by_label("joystick").rect();
    let c = rect.center();
    // Half way up: forward at half speed, no turn.
    h.hover_at(pos2(c.x, c.y - rect.height() / 4.0));
    h.drag_at(pos2(c.x, c.y - rect.height() / 4.0));
    h.run();
    let j = h.state();
    assert!(
        (j.v - 250.0).abs() < 5.0 && j.w.abs() < 0.5,
        "v {} w {}",
        j.v,
        j.w
    );
    // Drag to the top-left corner (and beyond): full speed, full left turn.
    h.hover_at(pos2(rect.left() - 50.0, rect.top() - 50.0));
    h.run();
    let j = h.state();
    assert!(
        (j.v - 500.0).abs() < 1e-3 && (j.w - 30.0).abs() < 1e-3,
        "v {} w {}",
        j.v,
        j.w
    );
    // Right and down: backwards, clockwise.
    h.hover_at(pos2(rect.right() - 1.0, rect.bottom() - 1.0));
    h.run();
    let j = h.state();
    assert!(j.v < -490.0 && j.w < -29.0, "v {} w {}", j.v, j.w);
    h.drop_at(pos2(rect.right() - 1.0, rect.bottom() - 1.0));
    h.run();
    let j = h.state();
    assert_eq!((j.v, j.w), (0.0, 0.0), "release stops");
}

#[test]
fn pantilt_pad_click_sets_longitude_and_latitude_within_limits() {
    let limits = PanTiltLimits {
        min_longitude: -150.0,
        max_longitude: 150.0,
        min_latitude: -40.0,
        max_latitude: 40.0,
    };
    let mut h = Harness::builder()
        .with_size(vec2(400.0, 400.0))
        .build_ui_state(
            |ui, p: &mut PanTiltPad| {
                p.show(ui, vec2(200.0, 100.0), None);
            },
            PanTiltPad::new("pantilt", limits),
        );
    h.run();
    let rect = h.get_by_label("pantilt").rect();
    // Three quarters to the right, one quarter down: pan right (negative), tilt up.
    let p = rect.min + vec2(rect.width() * 0.75, rect.height() * 0.25);
    click_at(&mut h, p);
    let s = h.state();
    assert!((s.longitude - -75.0).abs() < 2.0, "{}", s.longitude);
    assert!((s.latitude - 20.0).abs() < 2.0, "{}", s.latitude);
}

#[test]
fn world_view_click_sets_target_in_world_mm() {
    let mut h = Harness::builder()
        .with_size(vec2(500.0, 400.0))
        .build_ui_state(
            |ui, w: &mut WorldView| {
                let robot = Encoders::from_pose(0.0, 0.0, 0.0);
                w.show(
                    ui,
                    vec2(400.0, 300.0),
                    &WorldScene {
                        robot: Some(robot),
                        ..Default::default()
                    },
                );
            },
            WorldView::new("world"),
        );
    h.run();
    let rect: Rect = h.get_by_label("world").rect();
    // 4000 mm across 400 points: 10 mm per point. 100 right, 50 up of the centre.
    click_at(&mut h, rect.center() + vec2(100.0, -50.0));
    let t = h.state().target.expect("target set");
    assert!(
        (t[0] - 1000.0).abs() < 15.0 && (t[1] - 500.0).abs() < 15.0,
        "{t:?}"
    );
}

#[test]
fn wireframe_drag_orbits_the_virtual_camera() {
    let mut h = Harness::builder()
        .with_size(vec2(400.0, 400.0))
        .build_ui_state(
            |ui, w: &mut Wireframe3D| {
                let segs = [([0.0, 0.0, 0.0], [1000.0, 1000.0, 0.0], egui::Color32::WHITE)];
                w.show(ui, vec2(300.0, 300.0), &segs);
            },
            Wireframe3D::new("wireframe", OrbitCamera::default()),
        );
    h.run();
    let before = h.state().orbit;
    let rect = h.get_by_label("wireframe").rect();
    let c = rect.center();
    h.hover_at(c);
    h.drag_at(c);
    h.run();
    for i in 1..=4 {
        h.hover_at(c + vec2(10.0 * i as f32, -5.0 * i as f32));
        h.run();
    }
    h.drop_at(c + vec2(40.0, -20.0));
    h.run();
    let after = h.state().orbit;
    assert!(
        after.azimuth_deg != before.azimuth_deg,
        "drag right changes azimuth"
    );
    assert!(
        after.elevation_deg < before.elevation_deg,
        "drag up lowers the camera: {after:?}"
    );
}

#[test]
fn host_quit_button_and_ctrl_q_ask_to_close() {
    let rt = runtime_with(&[("myschema", Kind::Schema)]);
    let host = GuiHost::new(rt.clone());
    let mut h = Harness::builder()
        .with_size(vec2(900.0, 600.0))
        .build_ui_state(|ui, host: &mut GuiHost| host.ui(ui), host);
    h.run();
    assert!(!h.state().should_close());
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::Q);
    h.run();
    assert!(h.state().should_close(), "Ctrl+Q");

    let host = GuiHost::new(rt.clone());
    let handle = host.close_handle();
    let mut h = Harness::builder()
        .with_size(vec2(900.0, 600.0))
        .build_ui_state(|ui, host: &mut GuiHost| host.ui(ui), host);
    h.run();
    h.get_by_label("Quit").click();
    h.run();
    assert!(h.state().should_close(), "Quit button");
    // The shell's side: its handle closes too.
    assert!(!handle.requested());
    handle.close();
    assert!(handle.requested());
    // The Panels menu shows and hides a schema.
    h.get_by_label("Panels").click();
    h.run();
    h.get_by_label("myschema").click();
    h.run();
    assert!(rt.schema("myschema").expect("loaded").shown());
    rt.shutdown();
}

/// Panels open beside the docked mastergui, tiled, and stay there: none covers
/// mastergui's run and show columns, none covers another.
#[test]
fn panels_tile_beside_mastergui_and_never_cover_it() {
    let rt = runtime_with(&[
        ("gui", Kind::Service),
        ("mastergui", Kind::Schema),
        ("myschema", Kind::Schema),
        ("ping", Kind::Schema),
    ]);
    for s in ["mastergui", "myschema", "ping"] {
        rt.show(s).expect("show");
    }
    let host = GuiHost::new(rt.clone());
    let mut h = Harness::builder()
        .with_size(vec2(1400.0, 800.0))
        .build_ui_state(|ui, host: &mut GuiHost| host.ui(ui), host);
    h.run();
    h.run();
    let free = h.state().free_area().expect("free area drawn");
    let docked = h.get_by_label("run myschema").rect();
    assert!(
        docked.max.x <= free.min.x,
        "mastergui {docked:?} reaches into {free:?}"
    );
    let rects = h.state().panel_rects();
    assert_eq!(rects.len(), 2, "{rects:?}");
    for (name, r) in &rects {
        assert!(
            free.expand(1.0).contains_rect(*r),
            "{name}'s panel {r:?} leaves the free area {free:?}"
        );
    }
    assert!(
        !rects[0].1.intersects(rects[1].1),
        "panels overlap: {rects:?}"
    );
    rt.shutdown();
}

/// mastergui shows the recorder's line (time, messages, size, dropped) and its
/// record toggle starts and stops it, as the shell's `record start|stop`.
#[test]
fn mastergui_shows_and_toggles_the_recorder() {
    use std::sync::atomic::Ordering;
    struct Idle;
    impl jderobot::runtime::Driver for Idle {}
    let rt = runtime_with(&[("mastergui", Kind::Schema)]);
    rt.add_driver("recorder", Kind::Service, Box::new(Idle))
        .unwrap();
    let status = rt
        .names
        .export(
            "recorder",
            "status",
            jderobot::mcapfmt::RecorderStatus::default(),
        )
        .unwrap();
    status.messages.store(42, Ordering::Relaxed);
    let mut h = panel_harness(&rt, "mastergui", vec2(900.0, 700.0));
    h.run();
    h.get_by_label_contains("42 messages");
    h.get_by_label("record").click();
    h.run();
    assert!(
        status.want.load(Ordering::Acquire),
        "the toggle asks to record"
    );
    h.get_by_label("record").click();
    h.run();
    assert!(!status.want.load(Ordering::Acquire), "and to stop");
    rt.shutdown();
}
