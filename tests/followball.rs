//! followball on the simulator: a robot's pan-tilt camera keeps a red ball near the
//! image centre while a second robot pushes the ball and it rolls across the view.
//! The ball's position in the image is measured here, independently of followball's
//! HSV filter (a plain RGB test of each frame).
#![cfg(all(feature = "followball", feature = "simulator"))]

use crate::common;

use std::time::{Duration, Instant};

use common::{eventually, start_conf};
use jderobot::{
    interfaces::{Image, Motors, PtEncoders},
    world::LiveBalls,
};

/// The red blob's centroid and size, by a plain RGB test.
fn red_blob(img: &Image) -> Option<(f32, f32, usize)> {
    let (mut n, mut sx, mut sy) = (0usize, 0f64, 0f64);
    for (i, p) in img.data.chunks_exact(3).enumerate() {
        let (b, g, r) = (p[0] as u32, p[1] as u32, p[2] as u32);
        if r > 90 && r > 2 * g && r > 2 * b {
            n += 1;
            sx += (i % img.width as usize) as f64;
            sy += (i / img.width as usize) as f64;
        }
    }
    (n > 30).then(|| ((sx / n as f64) as f32, (sy / n as f64) as f32, n))
}

#[test]
fn keeps_a_rolling_ball_within_40_px_of_the_centre() {
    let dir = tempfile::tempdir().unwrap();
    let world = dir.path().join("ball.world");
    std::fs::write(
        &world,
        "floor_color 150,150,140\nfloor_tile 0\nwall_color beige\nroom -6000 -6000 9000 9000\n\
         ball 2000 -600 150 red 40\n",
    )
    .unwrap();
    let rt = start_conf(&format!(
        "driver simulator\nworld {}\nrobot robot1 0 0 0\nrobot robot2 2000 -1150 90\n\
         provides colorA\nprovides pantiltencoders\nprovides pantiltmotors\nprovides motors robot2\n\
         period camera 33\nperiod pantiltencoders 20\nend_driver\n\
         schema followball\nimage colorA\nend_schema\n\
         load_driver simulator\nload_schema followball\nrun followball\n",
        world.display()
    ));
    let cam = rt.interfaces.get::<Image>("colorA").unwrap();
    let pte = rt.interfaces.get::<PtEncoders>("pantiltencoders").unwrap();
    let push = rt.interfaces.get::<Motors>("motors.robot2").unwrap();
    let balls = rt
        .names
        .import::<LiveBalls>("world", "balls")
        .expect("the simulator exports its balls");
    let off_centre =
        |img: &Image| red_blob(img).map(|(x, y, _)| ((x - 160.0).hypot(y - 120.0), x, y));
    // At first the ball is off to the right and below (about 16° and 10°).
    eventually("a first frame", || cam.clock() > 0);
    let first = off_centre(&cam.read().value).expect("the ball is in view");
    assert!(first.0 > 50.0, "starts off centre: {first:?}");
    // It settles.
    eventually("the ball centred", || {
        off_centre(&cam.read().value).is_some_and(|d| d.0 < 20.0)
    });
    let pan0 = pte.read().pan_angle;
    let ball0 = balls.load()[0].pos;
    // Robot2 pushes the ball for 1.5 s, then stands still; the ball rolls on across
    // the camera's view. Every new frame from then on is measured.
    let t0 = Instant::now();
    let mut worst = (0.0f32, 0u64, (0.0f32, 0.0f32));
    let mut frames = 0;
    let mut last = cam.clock();
    let mut rolling_seen = Duration::ZERO;
    while t0.elapsed() < Duration::from_secs(9) {
        let v = if t0.elapsed() < Duration::from_millis(1500) {
            200.0
        } else {
            0.0
        };
        push.publish(Motors { v, w: 0.0 }).unwrap();
        let s = cam.snapshot();
        let speed = {
            let b = &balls.load()[0];
            b.vel[0].hypot(b.vel[1])
        };
        if s.clock != last {
            last = s.clock;
            // From half a second after the push began, while the ball rolls.
            if t0.elapsed() > Duration::from_millis(500) && speed > 60.0 {
                rolling_seen = t0.elapsed();
                frames += 1;
                let d = off_centre(&s.value).unwrap_or((f32::INFINITY, 0.0, 0.0));
                if d.0 > worst.0 {
                    worst = (d.0, s.clock, (d.1, d.2));
                }
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let ball1 = balls.load()[0].pos;
    let pan1 = pte.read().pan_angle;
    rt.shutdown();
    eprintln!(
        "worst {:.1} px over {frames} frames; ball rolled from {ball0:?} to {ball1:?}; pan {pan0:.1} -> {pan1:.1}",
        worst.0
    );
    let moved = (ball1[0] - ball0[0]).hypot(ball1[1] - ball0[1]);
    assert!(moved > 600.0, "the ball rolled {moved:.0} mm");
    assert!(
        rolling_seen > Duration::from_secs(3) && frames > 30,
        "measured {frames} frames over {rolling_seen:?} of rolling"
    );
    assert!(
        (pan1 - pan0).abs() > 10.0,
        "the head followed: pan {pan0:.1} -> {pan1:.1} deg"
    );
    assert!(
        worst.0 <= 40.0,
        "the ball was {:.1} px from the centre (frame {}, at {:?}); {frames} frames",
        worst.0,
        worst.1,
        worst.2
    );
}

#[test]
fn conf_errors_name_the_line() {
    for (body, expect) in [
        ("hmin 7\n", "test.conf:"),
        ("image laser\n", "not an image interface"),
        ("invert roll\n", "pan, tilt"),
        ("frobnicate\n", "takes no `frobnicate` line"),
    ] {
        let text = format!(
            "driver simulator\nprovides colorA\nprovides pantiltencoders\nprovides pantiltmotors\n\
             provides laser\nend_driver\nschema followball\n{body}end_schema\n\
             load_driver simulator\nload_schema followball\n"
        );
        let err = common::start_error(&text);
        assert!(err.contains(expect), "{body}: {err}");
    }
}

/// The panel draws the filtered image, the ball's offset and the pan-tilt commands.
#[cfg(feature = "gui")]
#[test]
fn panel_shows_offset_and_commands() {
    use egui_kittest::kittest::Queryable;
    let dir = tempfile::tempdir().unwrap();
    let world = dir.path().join("ball.world");
    std::fs::write(
        &world,
        "floor_tile 0\nroom -6000 -6000 9000 9000\nball 2000 -600 150 red\n",
    )
    .unwrap();
    let rt = start_conf(&format!(
        "driver simulator\nworld {}\nrobot robot1 0 0 0\nprovides colorA\nprovides pantiltencoders\n\
         provides pantiltmotors\nend_driver\nschema followball\nend_schema\n\
         load_driver simulator\nload_schema followball\nrun followball\n",
        world.display()
    ));
    let mut h = common::panel_harness(&rt, "followball", egui::vec2(420.0, 360.0));
    let mut seen = false;
    for _ in 0..200 {
        h.run();
        if h.query_by_label_contains("pixels ").is_some()
            && h.query_by_label_contains("pan to ").is_some()
        {
            seen = true;
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    rt.shutdown();
    assert!(seen, "the panel shows the offset and the commands");
}
