use super::*;
use crate::interfaces::{Encoders, Image, Laser, PtMotors};
use egui::{Color32, Rect, Vec2, pos2, vec2};

fn close(a: f32, b: f32, eps: f32) -> bool {
    (a - b).abs() <= eps
}

#[test]
fn fit_keeps_aspect_and_limits_zoom() {
    assert_eq!(
        fit_size(320, 240, vec2(640.0, 1000.0), 4.0),
        vec2(640.0, 480.0)
    );
    assert_eq!(
        fit_size(320, 240, vec2(1000.0, 240.0), 4.0),
        vec2(320.0, 240.0)
    );
    assert_eq!(fit_size(4, 2, vec2(1000.0, 1000.0), 4.0), vec2(16.0, 8.0));
    assert_eq!(fit_size(0, 240, vec2(100.0, 100.0), 4.0), Vec2::ZERO);
}

#[test]
fn pick_maps_screen_to_pixels() {
    let r = Rect::from_min_size(pos2(10.0, 20.0), vec2(640.0, 480.0));
    assert_eq!(pick_pixel(r, 320, 240, pos2(10.0, 20.0)), Some((0, 0)));
    assert_eq!(
        pick_pixel(r, 320, 240, pos2(649.9, 499.9)),
        Some((319, 239))
    );
    assert_eq!(pick_pixel(r, 320, 240, pos2(12.5, 23.9)), Some((1, 1)));
    assert_eq!(pick_pixel(r, 320, 240, pos2(650.0, 30.0)), None);
    assert_eq!(pick_pixel(r, 320, 240, pos2(9.0, 30.0)), None);
    let p = pixel_rect(r, 320, 240, 7, 9);
    assert_eq!(pick_pixel(r, 320, 240, p.center()), Some((7, 9)));
}

#[test]
fn bgr_becomes_rgb_and_bad_data_is_black() {
    let img = Image {
        width: 2,
        height: 1,
        data: vec![1, 2, 3, 4, 5, 6],
    };
    let c = bgr_to_color_image(&img);
    assert_eq!(
        c.pixels,
        vec![Color32::from_rgb(3, 2, 1), Color32::from_rgb(6, 5, 4)]
    );
    let short = Image {
        width: 2,
        height: 1,
        data: vec![1, 2, 3],
    };
    assert_eq!(bgr_to_color_image(&short).pixels[1], Color32::BLACK);
}

#[test]
fn polar_ahead_is_up_and_left_is_left() {
    let c = pos2(100.0, 100.0);
    let up = polar_to_screen(c, 0.01, 0.0, 1000.0);
    assert!(close(up.x, 100.0, 1e-3) && close(up.y, 90.0, 1e-3));
    let left = polar_to_screen(c, 0.01, 90.0, 1000.0);
    assert!(close(left.x, 90.0, 1e-3) && close(left.y, 100.0, 1e-3));
    let laser = Laser {
        readings: vec![1000; 361],
        resolution: 2.0,
        ..Laser::default()
    };
    let pts = laser_points(&laser);
    assert_eq!(pts[0].0, -90.0);
    assert_eq!(pts[180].0, 0.0);
    assert_eq!(pts[360].0, 90.0);
    assert_eq!(sonar_angles(16)[0], 90.0);
    assert_eq!(sonar_angles(4), vec![0.0, 90.0, 180.0, 270.0]);
}

#[test]
fn world_transform_round_trips_and_y_is_up() {
    let r = Rect::from_min_size(pos2(0.0, 0.0), vec2(400.0, 300.0));
    let t = WorldTransform::new(r, [1000.0, -500.0], 4000.0);
    assert_eq!(t.mm_per_px, 10.0);
    assert_eq!(t.to_screen([1000.0, -500.0]), r.center());
    let p = t.to_screen([2000.0, 0.0]);
    assert_eq!(p, pos2(300.0, 100.0));
    let w = t.to_world(pos2(37.0, 211.0));
    let back = t.to_screen(w);
    assert!(close(back.x, 37.0, 1e-3) && close(back.y, 211.0, 1e-3));
}

#[test]
fn zoom_keeps_the_point_under_the_cursor() {
    let r = Rect::from_min_size(pos2(0.0, 0.0), vec2(400.0, 300.0));
    let t = WorldTransform::new(r, [0.0, 0.0], 4000.0);
    let anchor = pos2(300.0, 50.0);
    let before = t.to_world(anchor);
    let (c, w) = zoom_about(&t, anchor, 2.0);
    assert_eq!(w, 2000.0);
    let after = WorldTransform::new(r, c, w).to_world(anchor);
    assert!(close(before[0], after[0], 1e-2) && close(before[1], after[1], 1e-2));
    // Limits.
    assert_eq!(zoom_about(&t, anchor, 1000.0).1, WORLD_WIDTH_RANGE.0);
    assert_eq!(zoom_about(&t, anchor, 0.0001).1, WORLD_WIDTH_RANGE.1);
}

#[test]
fn relative_and_absolute_coordinates_are_inverse() {
    let pose = Encoders::from_pose(1000.0, 2000.0, std::f32::consts::FRAC_PI_2);
    // 1 m ahead of a robot facing +y is at (1000, 3000).
    let w = relative_to_world(&pose, [1000.0, 0.0]);
    assert!(close(w[0], 1000.0, 1e-2) && close(w[1], 3000.0, 1e-2));
    let r = world_to_relative(&pose, [500.0, 2500.0]);
    let w2 = relative_to_world(&pose, r);
    assert!(close(w2[0], 500.0, 1e-2) && close(w2[1], 2500.0, 1e-2));
    // The laser reading straight ahead lands ahead of the robot.
    let laser = Laser {
        readings: vec![800; 181],
        resolution: 1.0,
        ..Laser::default()
    };
    let hits = laser_to_world(&pose, &laser);
    assert!(close(hits[90][0], 1000.0, 1e-2) && close(hits[90][1], 2800.0, 1e-2));
    // Reading 0 is on the robot's right: facing +y, right is +x.
    assert!(close(hits[0][0], 1800.0, 1e-2) && close(hits[0][1], 2000.0, 1e-2));
}

#[test]
fn joystick_maps_offsets_to_v_and_w() {
    assert_eq!(joystick_to_vw(vec2(0.0, 0.0), 500.0, 30.0), (-0.0, -0.0));
    assert_eq!(joystick_to_vw(vec2(0.0, -1.0), 500.0, 30.0), (500.0, -0.0));
    assert_eq!(joystick_to_vw(vec2(-1.0, 0.5), 500.0, 30.0), (-250.0, 30.0));
    assert_eq!(joystick_to_vw(vec2(3.0, -9.0), 500.0, 30.0), (500.0, -30.0));
    assert_eq!(joystick_to_vw(vec2(f32::NAN, 0.0), 500.0, 30.0).1, -0.0);
    let n = vw_to_joystick(250.0, -15.0, 500.0, 30.0);
    assert_eq!(joystick_to_vw(n, 500.0, 30.0), (250.0, -15.0));
    let r = Rect::from_min_size(pos2(0.0, 0.0), vec2(200.0, 100.0));
    assert_eq!(normalized_offset(r, pos2(200.0, 0.0)), vec2(1.0, -1.0));
}

#[test]
fn pantilt_pad_maps_to_limits_and_back() {
    let l = PanTiltLimits::from(&PtMotors::default());
    let (lon, lat) = pad_to_pantilt(vec2(-1.0, -1.0), &l);
    assert_eq!((lon, lat), (l.max_longitude, l.max_latitude));
    let (lon, lat) = pad_to_pantilt(vec2(1.0, 1.0), &l);
    assert_eq!((lon, lat), (l.min_longitude, l.min_latitude));
    let n = pantilt_to_pad(10.0, -20.0, &l);
    let (lon, lat) = pad_to_pantilt(n, &l);
    assert!(close(lon, 10.0, 1e-3) && close(lat, -20.0, 1e-3));
}

#[test]
fn time_plot_keeps_its_window() {
    let mut p = TimePlot::new("t", 10.0);
    assert!(p.is_empty());
    for i in 0..30 {
        p.push_at("a", i as f64, i as f64);
    }
    let pts = p.points("a");
    assert_eq!(pts.first(), Some(&[19.0, 19.0]));
    assert_eq!(pts.len(), 11);
    assert!(p.points("b").is_empty());
}

#[test]
fn orbit_camera_sees_its_target_at_the_image_centre() {
    let o = OrbitCamera {
        target: [1000.0, 2000.0, 500.0],
        ..Default::default()
    };
    let p = o.position();
    let d = ((p[0] - 1000.0).powi(2) + (p[1] - 2000.0).powi(2) + (p[2] - 500.0).powi(2)).sqrt();
    assert!((d - o.distance).abs() < 1e-6);
    let cam = o.camera(400, 300);
    let seg =
        project_segment(&cam, [1000.0, 2000.0, 500.0], [1000.0, 2000.0, 600.0]).expect("visible");
    assert!(
        close(seg.0.x, 200.0, 1.5) && close(seg.0.y, 150.0, 1.5),
        "{seg:?}"
    );
    // "Up" in the world is up on the screen.
    assert!(seg.1.y < seg.0.y, "{seg:?}");
    // A segment behind the camera is not drawn.
    let behind = [
        p[0] + (p[0] - 1000.0),
        p[1] + (p[1] - 2000.0),
        p[2] + (p[2] - 500.0),
    ];
    assert!(project_segment(&cam, behind, [behind[0] + 1.0, behind[1], behind[2]]).is_none());
    // Orbiting and zooming stay within limits.
    let o2 = o.dragged(vec2(20.0, 1000.0)).zoomed(1.0e6);
    assert_eq!(o2.elevation_deg, 89.0);
    assert_eq!(o2.distance, ORBIT_DISTANCE_RANGE.0);
    assert!(close(
        o2.azimuth_deg as f32,
        (o.azimuth_deg - 10.0).rem_euclid(360.0) as f32,
        1e-4
    ));
}
