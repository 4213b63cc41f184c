//! progeo: projection, backprojection, displayline, conventions and file formats.

use std::path::Path;

use jderobot::progeo::{
    GAZEBO_FOV, GlCamera, HPoint2D, HPoint3D, PinholeCamera, ProgeoError, StereoCamera, WEBOTS_FOV,
    World, focal_from_fov, fov_from_focal, graphic_to_optical, optical_to_graphic,
};

fn close(a: f64, b: f64, eps: f64) -> bool {
    (a - b).abs() <= eps
}

#[test]
fn cam_in_hand_computed_projection() {
    let cam = PinholeCamera::load("assets/cameras/cam-in").unwrap();
    assert_eq!((cam.columns, cam.rows), (320, 240));
    // A point on the optical axis projects to the optical centre (u0, v0).
    let c = cam.project(HPoint3D::point(0.0, 5298.8, 0.0));
    assert!(close(c.x, 120.0, 1e-9) && close(c.y, 160.0, 1e-9) && c.h == 1.0);
    // 1000 mm ahead, 100 mm to the right (+X), 50 mm up (+Z):
    // x (rows, up) = fx*50/1000 + u0, y (columns) = fx*100/1000 + v0.
    let p = cam.project(HPoint3D::point(100.0, 2298.8, 50.0));
    assert!(close(p.x, 505.85 * 0.05 + 120.0, 1e-9), "{p:?}");
    assert!(close(p.y, 505.85 * 0.1 + 160.0, 1e-9), "{p:?}");
    // Behind the camera: h = -1.
    assert_eq!(cam.project(HPoint3D::point(0.0, 0.0, 0.0)).h, -1.0);
    // In the camera plane: at infinity.
    assert_eq!(cam.project(HPoint3D::point(10.0, 1298.8, 0.0)).h, 0.0);
}

#[test]
fn project_backproject_round_trip() {
    for file in ["assets/cameras/cam-in", "assets/cameras/isight-640x480"] {
        let mut cam = PinholeCamera::load(file).unwrap();
        cam.skew = 0.01;
        cam.update_camera_matrix();
        for &(x, y) in &[(0.0, 0.0), (120.0, 160.0), (17.5, 300.25), (239.0, 319.0)] {
            let p = HPoint2D::new(x, y, 1.0);
            let q = cam.backproject(p).unwrap();
            // 4.3's backproject returns the point at depth fx along the ray.
            let pos = cam.position;
            let d = ((q.x - pos.x).powi(2) + (q.y - pos.y).powi(2) + (q.z - pos.z).powi(2)).sqrt();
            assert!(d >= cam.fdistx - 1e-6, "{file}: depth {d}");
            let r = cam.project(q);
            assert!(
                close(r.x, x, 1e-6) && close(r.y, y, 1e-6) && r.h == 1.0,
                "{file}: {r:?}"
            );
        }
        // And 3D -> 2D -> ray: the point lies on the ray through its pixel.
        let w = HPoint3D::point(1000.0, 3000.0, 800.0);
        if let Some(px) = cam.project_visible(w) {
            let dir = cam.ray(px).unwrap();
            let v = nalgebra::Vector3::new(
                w.x - cam.position.x,
                w.y - cam.position.y,
                w.z - cam.position.z,
            );
            assert!(v.normalize().dot(&dir) > 1.0 - 1e-9);
        }
    }
    assert!(
        PinholeCamera::default()
            .backproject(HPoint2D::new(1.0, 1.0, 0.0))
            .is_none()
    );
}

#[test]
fn roll_rotates_the_image_about_the_centre() {
    let mut cam = PinholeCamera::default();
    let w = HPoint3D::point(100.0, 2298.8, 0.0); // to the right of the axis
    let p0 = cam.project(w);
    cam.roll = std::f64::consts::FRAC_PI_2;
    cam.update_camera_matrix();
    let p1 = cam.project(w);
    // A quarter turn moves the column offset onto the row axis (same distance).
    let (d0, d1) = ((p0.x - 120.0, p0.y - 160.0), (p1.x - 120.0, p1.y - 160.0));
    assert!(close(d0.0, 0.0, 1e-9));
    assert!(
        close(d1.0.abs(), d0.1.abs(), 1e-9) && close(d1.1, 0.0, 1e-9),
        "{p1:?}"
    );
}

#[test]
fn pixel_conventions() {
    // The manual's GRAPHIC_TO_OPTICAL macros for 240 rows.
    assert_eq!(graphic_to_optical(10.0, 0.0, 240), (239.0, 10.0));
    assert_eq!(optical_to_graphic(239.0, 10.0, 240), (10.0, 0.0));
    for &(c, r) in &[(0.0, 0.0), (319.0, 239.0), (5.5, 7.25)] {
        let (x, y) = graphic_to_optical(c, r, 240);
        assert_eq!(optical_to_graphic(x, y, 240), (c, r));
    }
    // A point above the optical axis appears in the upper half of the image.
    let cam = PinholeCamera::default();
    let up = cam.project(HPoint3D::point(0.0, 5298.8, 500.0));
    let (_, row) = cam.optical_to_graphic(up);
    assert!(row < 119.0, "row {row}");
    let (col, row) = cam.optical_to_graphic(cam.graphic_to_optical(3.0, 4.0));
    assert_eq!((col, row), (3.0, 4.0));
}

#[test]
fn intrinsics_from_opengl_fov() {
    // Gazebo: 60 degrees on the height: 240 / (2 tan 30°) = 207.846...
    assert!(close(
        focal_from_fov(240.0, GAZEBO_FOV),
        207.84609690826525,
        1e-9
    ));
    let mut cam = PinholeCamera::default();
    cam.set_intrinsics_from_fov(GAZEBO_FOV, true);
    assert_eq!((cam.u0, cam.v0), (120.0, 160.0));
    assert!(close(cam.fdistx, 207.84609690826525, 1e-9));
    // The manual's 640x480 example: fdisty = 480 / (2 tan 22.5°).
    assert!(close(
        focal_from_fov(480.0, 45f64.to_radians()),
        579.4112549695428,
        1e-9
    ));
}

#[test]
fn displayline_clips_to_the_image() {
    let cam = PinholeCamera::default();
    let xmax = 239.0;
    let ymax = 319.0;
    let inside =
        |p: &HPoint2D| p.x >= -1e-9 && p.x <= xmax + 1e-9 && p.y >= -1e-9 && p.y <= ymax + 1e-9;
    // Both inside: unchanged.
    let (a, b) = cam
        .displayline(
            HPoint2D::new(10.0, 20.0, 1.0),
            HPoint2D::new(100.0, 200.0, 1.0),
        )
        .unwrap();
    assert_eq!((a.x, a.y, b.x, b.y), (10.0, 20.0, 100.0, 200.0));
    // One outside: clipped at the border y = 319.
    let (a, b) = cam
        .displayline(
            HPoint2D::new(100.0, 100.0, 1.0),
            HPoint2D::new(100.0, 1000.0, 1.0),
        )
        .unwrap();
    assert_eq!((a.x, a.y), (100.0, 100.0));
    assert!(close(b.x, 100.0, 1e-9) && close(b.y, ymax, 1e-9));
    // Both outside, crossing: both ends on borders.
    let (a, b) = cam
        .displayline(
            HPoint2D::new(-50.0, 160.0, 1.0),
            HPoint2D::new(400.0, 160.0, 1.0),
        )
        .unwrap();
    assert!(close(a.x, 0.0, 1e-9) && close(b.x, xmax, 1e-9));
    // Both outside, missing the image; both behind: invisible.
    assert!(
        cam.displayline(
            HPoint2D::new(-5.0, -5.0, 1.0),
            HPoint2D::new(-50.0, 500.0, 1.0)
        )
        .is_none()
    );
    assert!(
        cam.displayline(
            HPoint2D::new(5.0, 5.0, -1.0),
            HPoint2D::new(50.0, 50.0, -1.0)
        )
        .is_none()
    );
    // A 3D segment crossing the camera plane (4.3.0 drew nothing): the visible part
    // runs from the point in front to the image border, away from the other image.
    let front = HPoint3D::point(0.0, 3298.8, 0.0); // on the axis, 2 m ahead
    let behind = HPoint3D::point(0.0, 298.8, -500.0); // 1 m behind, below
    let (p1, p2) = (cam.project(front), cam.project(behind));
    assert_eq!((p1.h, p2.h), (1.0, -1.0));
    let (a, b) = cam.displayline(p1, p2).unwrap();
    assert!(close(a.x, 120.0, 1e-9) && close(a.y, 160.0, 1e-9));
    assert!(inside(&b));
    // Points of the segment just in front of the plane project downwards (x small).
    let near = HPoint3D::point(0.0, 1299.8, -333.1);
    let pn = cam.project(near);
    assert!(pn.h == 1.0 && pn.x < 0.0, "{pn:?}");
    assert!(close(b.x, 0.0, 1e-9), "{b:?}");
    // Swapped order gives the same segment.
    let (c, d) = cam.displayline(p2, p1).unwrap();
    assert!(close(c.x, a.x, 1e-9) && close(d.x, b.x, 1e-9));
}

#[test]
fn camera_info_display() {
    let s = PinholeCamera::default().to_string();
    for needle in [
        "Position",
        "Focus of Attention",
        "Roll",
        "fx=505.8500",
        "(u0,v0)=(120.0000,160.0000)",
        "K matrix",
        "RT matrix",
    ] {
        assert!(s.contains(needle), "missing {needle} in\n{s}");
    }
}

#[test]
fn camera_file_round_trip() {
    let mut cam = PinholeCamera::load("assets/cameras/isight-640x480").unwrap();
    assert!(close(cam.roll, 3.007, 1e-12) && cam.columns == 640 && cam.rows == 480);
    cam.name = String::new();
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("cam-out");
    cam.save(&f).unwrap();
    let text = std::fs::read_to_string(&f).unwrap();
    assert!(text.starts_with("#extrinsics, position\npositionX 4000.000000\n"));
    assert!(text.contains("\n #intrinsics\nfx 405.400000\n"));
    assert!(text.ends_with("columns 640\nrows 480\n"));
    let back = PinholeCamera::load(&f).unwrap();
    assert_eq!(back, cam);
    // `f` sets both focal distances.
    let c = PinholeCamera::parse("f 300\nrows 10\ncolumns 20\n", Path::new("x")).unwrap();
    assert_eq!(
        (c.fdistx, c.fdisty, c.rows, c.columns),
        (300.0, 300.0, 10, 20)
    );
}

#[test]
fn camera_file_errors_name_file_and_line() {
    let e = PinholeCamera::parse("# c\npositionX 1\nfx abc\n", Path::new("cam")).unwrap_err();
    assert_eq!(e.to_string(), "cam:3: `fx abc`: expected a number");
    let e = PinholeCamera::parse("rows 12.5\n", Path::new("cam")).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("cam:1: `rows 12.5`: expected a whole number"),
        "{e}"
    );
    let e = PinholeCamera::parse("roll\n", Path::new("cam")).unwrap_err();
    assert_eq!(e.to_string(), "cam:1: `roll` needs a number after it");
    let e = PinholeCamera::parse("FOApositionY 1298.8\n", Path::new("cam")).unwrap_err();
    assert!(matches!(e, ProgeoError::Invalid { .. }), "{e}");
    assert!(matches!(
        PinholeCamera::load("/nonexistent/cam"),
        Err(ProgeoError::Io { .. })
    ));
}

#[test]
fn world_file_round_trip_and_errors() {
    let w = World::load("assets/cameras/room.world").unwrap();
    assert_eq!(w.lines.len(), 12);
    assert_eq!(
        w.camera_in.as_deref(),
        Some(Path::new("assets/cameras/cam-in"))
    );
    assert_eq!(w.bounds[4], Some(2880.0));
    assert_eq!(w.lines[0].1, HPoint3D::point(2000.0, 0.0, 0.0));
    let back = World::parse(&w.to_file_string(), Path::new("again")).unwrap();
    assert_eq!(back, w);
    let e = World::parse("\nworldline 1 2 3 1 4 5 6\n", Path::new("w")).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("w:2: `worldline 1 2 3 1 4 5 6`: expected 8 numbers"),
        "{e}"
    );
    // cam-in sits on the floor (Z = 0) looking along +Y: its view (±17.6° wide,
    // ±13.4° high) sees only the far floor edge, on the horizon row u0 = 120,
    // clipped to the full width; the walls' corners and the ceiling are outside.
    let cam = PinholeCamera::load(w.camera_in.as_ref().unwrap()).unwrap();
    let drawn: Vec<_> = w
        .lines
        .iter()
        .filter_map(|(a, b)| cam.displayline(cam.project(*a), cam.project(*b)))
        .collect();
    assert_eq!(drawn.len(), 1, "{drawn:?}");
    let (a, b) = drawn[0];
    assert!((a.x - 120.0).abs() < 1e-6 && (b.x - 120.0).abs() < 1e-6);
    assert!((a.y - b.y).abs() > 318.9, "{drawn:?}");
    for (a, b) in drawn {
        for p in [a, b] {
            assert!(
                p.x >= -1e-6 && p.x <= 239.0 + 1e-6 && p.y >= -1e-6 && p.y <= 319.0 + 1e-6,
                "{p:?}"
            );
        }
    }
}

#[test]
fn stereo_cameras_are_baseline_apart() {
    let mut s = StereoCamera {
        position: HPoint3D::point(0.0, 0.0, 1000.0),
        foa: HPoint3D::point(0.0, 1000.0, 1000.0),
        roll: 0.0,
        camera1: PinholeCamera::default(),
        camera2: PinholeCamera::default(),
        baseline: 120.0,
        name: "bumblebee".into(),
    };
    s.update_stereocamera_matrix();
    let (a, b) = (s.camera1.position, s.camera2.position);
    assert!(close(
        ((a.x - b.x).powi(2) + (a.y - b.y).powi(2) + (a.z - b.z).powi(2)).sqrt(),
        120.0,
        1e-9
    ));
    // A far point on the rig's axis has a positive disparity along the columns.
    let p = HPoint3D::point(0.0, 5000.0, 1000.0);
    let (l, r) = (s.camera1.project(p), s.camera2.project(p));
    assert!(close(l.x, r.x, 1e-9) && (l.y - r.y).abs() > 1.0);
}

/// The pixel (optical x, y) where OpenGL's matrices put `p`: clip = P · V · p,
/// window = (ndc + 1) / 2 · size, minus the half pixel of the pixel centre.
fn gl_pixel(cam: &PinholeCamera, p: [f64; 3]) -> (f64, f64) {
    let clip = cam.gl_projection(10.0, 1.0e5)
        * cam.gl_view()
        * nalgebra::Vector4::new(p[0], p[1], p[2], 1.0);
    let (xn, yn) = (clip.x / clip.w, clip.y / clip.w);
    let col = (xn + 1.0) / 2.0 * cam.columns as f64 - 0.5;
    let row_up = (yn + 1.0) / 2.0 * cam.rows as f64 - 0.5;
    (row_up, col)
}

/// OpenGL's matrices of `cam` put each of `points` on progeo's pixel.
fn assert_gl_on_progeo(cam: &PinholeCamera, points: &[[f64; 3]]) {
    for &p in points {
        let q = cam.project(HPoint3D::point(p[0], p[1], p[2]));
        assert_eq!(q.h, 1.0);
        let (x, y) = gl_pixel(cam, p);
        assert!(
            close(x, q.x, 1e-6) && close(y, q.y, 1e-6),
            "{p:?}: gl ({x}, {y}) progeo ({}, {})",
            q.x,
            q.y
        );
    }
}

#[test]
fn opengl_camera_to_progeo_and_back_gazebo() {
    // The manual's Gazebo camera: 320x240, aperture 60 degrees on the height, so
    // f = 240 / (2 tan 30°) = 207.846 and the optical centre is (120, 160).
    let gl = GlCamera {
        position: [0.0, 0.0, 1000.0],
        foa: [4000.0, 500.0, 800.0],
        roll: 0.0,
        fovy: GAZEBO_FOV,
        aspect: 320.0 / 240.0,
        near: 10.0,
        far: 1.0e5,
    };
    let cam = gl.to_progeo(320, 240);
    assert!(
        close(cam.fdistx, 207.84609690826525, 1e-9),
        "{}",
        cam.fdistx
    );
    assert!(
        close(cam.fdisty, 207.84609690826525, 1e-9),
        "{}",
        cam.fdisty
    );
    assert_eq!((cam.u0, cam.v0, cam.skew), (120.0, 160.0, 0.0));
    let back = GlCamera::from_progeo(&cam, 10.0, 1.0e5);
    assert!(close(back.fovy, GAZEBO_FOV, 1e-12), "{}", back.fovy);
    assert!(close(back.aspect, 320.0 / 240.0, 1e-12));
    assert_eq!((back.position, back.foa), (gl.position, gl.foa));
    // OpenGL's matrices put points on progeo's pixels.
    assert_gl_on_progeo(
        &cam,
        &[
            [4000.0, 500.0, 800.0],
            [3000.0, -900.0, 0.0],
            [2500.0, 1200.0, 1900.0],
        ],
    );
}

#[test]
fn opengl_camera_to_progeo_and_back_webots() {
    // The manual's Webots camera: 320x240, aperture 45 degrees (0.785398 rad) on
    // the width, so f = 320 / (2 tan 22.5°) = 386.274.
    let gl = GlCamera::from_horizontal_fov([0.0; 3], [0.0, 1000.0, 0.0], WEBOTS_FOV, 320.0 / 240.0);
    assert!(close(gl.fovx(), WEBOTS_FOV, 1e-12));
    let cam = gl.to_progeo(320, 240);
    let f = focal_from_fov(320.0, WEBOTS_FOV);
    assert!(close(f, 386.2741699796952, 1e-9), "{f}");
    assert!(
        close(cam.fdistx, f, 1e-9) && close(cam.fdisty, f, 1e-9),
        "{} {}",
        cam.fdistx,
        cam.fdisty
    );
    assert_eq!((cam.u0, cam.v0), (120.0, 160.0));
    assert!(close(fov_from_focal(320.0, cam.fdisty), WEBOTS_FOV, 1e-12));
    let back = GlCamera::from_progeo(&cam, 10.0, 1.0e5);
    assert!(close(back.fovx(), WEBOTS_FOV, 1e-12), "{}", back.fovx());
    assert!(close(back.fovy, gl.fovy, 1e-12));
    // An off-centre optical centre, unequal focal distances and skew still land on
    // progeo's pixels.
    let mut odd = cam.clone();
    odd.u0 = 131.0;
    odd.v0 = 149.5;
    odd.fdisty = 402.0;
    odd.skew = 0.01;
    odd.roll = 0.2;
    odd.update_camera_matrix();
    assert_gl_on_progeo(&odd, &[[100.0, 1000.0, 50.0], [-300.0, 2500.0, -200.0]]);
}
