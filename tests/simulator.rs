//! The simulator: the deterministic core through its public API (`Sim::step`),
//! and the driver through the real registry and runtime. No test depends on
//! timing: driver tests poll for a state with a generous bound.
#![cfg(feature = "simulator")]

use crate::common;

use common::{eventually, root, start_conf, world_path};
use std::{path::Path, sync::Arc, time::Duration};

use jderobot::{
    ComponentConf, Conf, Runtime,
    conf::Kind,
    drivers::simulator::{Renderer, RobotModel, Sim, Simulation},
    interfaces::{Encoders, Image, Interface, Laser, Motors, PtMotors},
    progeo::{self, HPoint3D},
    world::{self, BallSpec, World},
};

const DT: f64 = 0.01;

/// A 4 m x 4 m room, walls 1 m high.
fn room() -> World {
    let mut w = World::new();
    w.add_room([0.0, 0.0], [4000.0, 4000.0], 1000.0, [200, 200, 200]);
    w
}

/// A model with (practically) no acceleration limit, for exact kinematics.
fn snappy() -> RobotModel {
    RobotModel {
        accel_v: 1e9,
        accel_w: 1e9,
        ..RobotModel::default()
    }
}

fn run(sim: &mut Sim, seconds: f64) {
    for _ in 0..(seconds / DT).round() as usize {
        sim.step(DT);
    }
}

#[test]
fn driving_into_a_wall_stops_at_the_wall() {
    let mut sim = Sim::new(room(), 1);
    let r = sim.add_robot("r", RobotModel::default(), 1000.0, 2000.0, 0.0);
    sim.set_motors(r, Motors { v: 800.0, w: 0.0 });
    let mut max_x: f64 = 0.0;
    for _ in 0..1500 {
        sim.step(DT);
        max_x = max_x.max(sim.robots[r].pose.x);
    }
    let robot = &sim.robots[r];
    let radius = robot.model.radius;
    // It never went through the wall, and it stands right against it.
    assert!(max_x <= 4000.0 - radius, "went into the wall: x = {max_x}");
    assert!(
        robot.pose.x > 4000.0 - radius - 1.0,
        "stopped short: x = {}",
        robot.pose.x
    );
    assert!((robot.pose.y - 2000.0).abs() < 1e-6);
    assert!(robot.stalled && robot.v == 0.0);
    assert_eq!(robot.bumpers.iter().filter(|&&b| b == 1).count(), 1);
    assert_eq!(
        robot.bumpers[2], 1,
        "the middle front bumper: {:?}",
        robot.bumpers
    );
    // Odometry reports where it really went (no noise).
    let e = sim.encoders(r);
    assert!((e.x as f64 - robot.pose.x).abs() < 0.01);
    // Backing away works.
    sim.set_motors(r, Motors { v: -300.0, w: 0.0 });
    run(&mut sim, 2.0);
    assert!(sim.robots[r].pose.x < 4000.0 - radius - 100.0);
    assert!(!sim.robots[r].stalled);
}

#[test]
fn a_wall_stops_a_turning_robot_and_other_robots_are_obstacles() {
    let mut sim = Sim::new(room(), 1);
    let a = sim.add_robot("a", RobotModel::default(), 1000.0, 1000.0, 45.0);
    let b = sim.add_robot("b", RobotModel::default(), 2000.0, 2000.0, 0.0);
    sim.set_motors(a, Motors { v: 500.0, w: 0.0 });
    run(&mut sim, 10.0);
    let (pa, pb) = (sim.robots[a].pose, sim.robots[b].pose);
    let d = (pa.x - pb.x).hypot(pa.y - pb.y);
    assert!((500.0 - 1e-6..502.0).contains(&d), "robots at {d} mm");
    // Along an arc into a wall: still stops before it.
    let mut sim = Sim::new(room(), 1);
    let r = sim.add_robot("r", RobotModel::default(), 2000.0, 2000.0, 0.0);
    sim.set_motors(r, Motors { v: 600.0, w: 10.0 });
    for _ in 0..3000 {
        sim.step(DT);
        let p = sim.robots[r].pose;
        for c in [p.x, p.y] {
            assert!(
                (250.0 - 1e-6..=3750.0 + 1e-6).contains(&c),
                "inside a wall at {p:?}"
            );
        }
    }
}

/// Distance from (x, y) along angle `a` to the walls of the 4 m room.
fn to_room_walls(x: f64, y: f64, a: f64) -> f64 {
    let (dx, dy) = (a.cos(), a.sin());
    let mut best = f64::INFINITY;
    for (d, o, lo, hi) in [(dx, x, 0.0, 4000.0), (dy, y, 0.0, 4000.0)] {
        if d.abs() > 1e-12 {
            for wall in [lo, hi] {
                let t = (wall - o) / d;
                if t > 0.0 {
                    best = best.min(t);
                }
            }
        }
    }
    best
}

#[test]
fn laser_ranges_equal_the_geometry() {
    let mut sim = Sim::new(room(), 1);
    let r = sim.add_robot("r", RobotModel::default(), 1000.0, 1500.0, 30.0);
    let mut laser = Laser::default();
    sim.laser(r, &mut laser);
    assert_eq!(laser.readings.len(), 180);
    assert_eq!(laser.resolution, 1.0);
    let th = 30f64.to_radians();
    // The laser is 19 mm ahead of the robot's centre.
    let (lx, ly) = (1000.0 + 19.0 * th.cos(), 1500.0 + 19.0 * th.sin());
    for (i, &got) in laser.readings.iter().enumerate() {
        let a = th + (-90.0 + i as f64).to_radians();
        let want = to_room_walls(lx, ly, a).min(8000.0);
        assert!(
            (got as f64 - want).abs() <= 1.0,
            "reading {i}: {got} vs {want}"
        );
    }
    // Straight ahead from a robot facing east at (1000, 2000): 4000 - 1019.
    let mut sim = Sim::new(room(), 1);
    let r = sim.add_robot("r", RobotModel::default(), 1000.0, 2000.0, 0.0);
    sim.laser(r, &mut laser);
    assert_eq!(laser.readings[90], 2981);
    assert_eq!(laser.readings[0], 2000); // right: the south wall
    // Other count and resolution: 360 readings at 2 per degree.
    sim.robots[r].model.laser_count = 360;
    sim.robots[r].model.laser_resolution = 2.0;
    sim.laser(r, &mut laser);
    assert_eq!((laser.readings.len(), laser.resolution), (360, 2.0));
    assert_eq!(laser.readings[180], 2981);
    // A ball in front is seen at its surface.
    let mut w = room();
    w.add_ball(BallSpec {
        pos: [2500.0, 2000.0],
        radius: 110.0,
        color: [255, 0, 0],
        friction: 300.0,
    });
    let mut sim = Sim::new(w, 1);
    let r = sim.add_robot("r", RobotModel::default(), 1000.0, 2000.0, 0.0);
    sim.laser(r, &mut laser);
    assert_eq!(laser.readings[90], 2500 - 110 - 1019);
}

#[test]
fn sonars_are_the_pioneer_ring() {
    let mut sim = Sim::new(room(), 1);
    let r = sim.add_robot("r", RobotModel::default(), 2000.0, 2000.0, 0.0);
    let mut s = jderobot::interfaces::Sonars::default();
    sim.sonars(r, &mut s);
    assert_eq!(s.us.len(), 16);
    // Sonar 0 at (115, 130) looks left (90 deg): the north wall is 2000 - 130 away.
    assert!((s.us[0] - 1870.0).abs() < 1.0, "{:?}", s.us);
    // Sonar 3 at (210, 25) looks 10 deg left of ahead: the east wall, in its cone.
    assert!(s.us[3] > 1780.0 && s.us[3] < 1830.0, "{:?}", s.us);
}

#[test]
fn odometry_integrates_v_and_w() {
    let mut sim = Sim::new(World::new(), 1);
    let r = sim.add_robot("r", snappy(), 100.0, 200.0, 0.0);
    sim.set_motors(r, Motors { v: 200.0, w: 0.0 });
    run(&mut sim, 5.0);
    let e = sim.encoders(r);
    assert!(
        (e.x - 1100.0).abs() < 0.01 && (e.y - 200.0).abs() < 0.01,
        "{e:?}"
    );
    sim.set_motors(r, Motors { v: 0.0, w: 30.0 });
    run(&mut sim, 3.0);
    let e = sim.encoders(r);
    assert!(
        (e.theta - std::f32::consts::FRAC_PI_2).abs() < 1e-4,
        "{e:?}"
    );
    assert!(e.cos.abs() < 1e-4 && (e.sin - 1.0).abs() < 1e-4);
    // An arc: v = 100 mm/s, w = 10 deg/s for 9 s turns 90 degrees on a circle of
    // radius v/w = 572.96 mm, from heading north at (1100, 200).
    sim.set_motors(r, Motors { v: 100.0, w: 10.0 });
    run(&mut sim, 9.0);
    let e = sim.encoders(r);
    let rad = 100.0 / 10f64.to_radians();
    assert!((e.x as f64 - (1100.0 - rad)).abs() < 0.05, "{e:?}");
    assert!((e.y as f64 - (200.0 + rad)).abs() < 0.05, "{e:?}");
    assert!(
        (e.theta as f64 - std::f64::consts::PI).abs() < 1e-4,
        "{e:?}"
    );
    // The seed's limits: |v| <= 1000 mm/s, |w| <= 180 deg/s.
    sim.set_motors(r, Motors { v: 5000.0, w: 0.0 });
    let e0 = sim.encoders(r);
    run(&mut sim, 1.0);
    let e1 = sim.encoders(r);
    assert!(
        ((e1.x - e0.x).hypot(e1.y - e0.y) - 1000.0).abs() < 0.1,
        "{e0:?} {e1:?}"
    );
    sim.set_motors(r, Motors { v: 0.0, w: -500.0 });
    run(&mut sim, 0.5);
    // θ stays in (0, 2π]: from π, −90 degrees.
    assert!((sim.encoders(r).theta as f64 - std::f64::consts::FRAC_PI_2).abs() < 1e-4);
}

#[test]
fn acceleration_is_limited() {
    let mut sim = Sim::new(World::new(), 1);
    let r = sim.add_robot("r", RobotModel::default(), 0.0, 0.0, 0.0);
    sim.set_motors(r, Motors { v: 600.0, w: 90.0 });
    run(&mut sim, 1.0);
    // Pioneer defaults: 300 mm/s², 100 deg/s².
    assert!((sim.robots[r].v - 300.0).abs() < 1e-6);
    assert!((sim.robots[r].w - 90.0).abs() < 1e-6);
    assert!((sim.robots[r].pose.x.hypot(sim.robots[r].pose.y) - 150.0).abs() < 10.0);
}

#[test]
fn noise_is_seeded_and_off_by_default() {
    let drive = |seed: u64, noisy: bool| -> Encoders {
        let mut sim = Sim::new(World::new(), seed);
        if noisy {
            sim.noise.odometry_distance = 0.05;
            sim.noise.odometry_angle = 0.05;
        }
        let r = sim.add_robot("r", snappy(), 0.0, 0.0, 0.0);
        sim.set_motors(r, Motors { v: 300.0, w: 20.0 });
        run(&mut sim, 5.0);
        sim.encoders(r)
    };
    assert_eq!(drive(1, false), drive(2, false));
    assert_eq!(drive(7, true), drive(7, true));
    assert_ne!(drive(7, true), drive(8, true));
    assert_ne!(drive(7, true), drive(7, false));
}

/// The centroid of the red pixels in progeo's optical coordinates (pixel (column
/// c, row r) is optical [rows−1−r, rows−r) x [c, c+1)), and their number.
fn red_centroid(img: &Image) -> Option<(f64, f64, usize)> {
    let (mut sx, mut sy, mut n) = (0.0, 0.0, 0usize);
    for row in 0..img.height {
        for col in 0..img.width {
            let [b, g, r] = img.pixel(col, row);
            if r > 90 && g < 60 && b < 60 {
                let (x, y) = progeo::graphic_to_optical(col as f64, row as f64, img.height);
                sx += x + 0.5;
                sy += y + 0.5;
                n += 1;
            }
        }
    }
    (n > 0).then(|| (sx / n as f64, sy / n as f64, n))
}

#[test]
fn the_camera_sees_a_red_ball_where_progeo_projects_it() {
    let mut w = room();
    let ball = [2600.0, 1700.0, 110.0];
    w.add_ball(BallSpec {
        pos: [ball[0], ball[1]],
        radius: ball[2],
        color: [220, 20, 20],
        friction: 300.0,
    });
    let mut sim = Sim::new(w, 1);
    let r = sim.add_robot("r", snappy(), 1000.0, 2000.0, 0.0);
    let mut rend = Renderer::new();
    let mut img = Image::new(320, 240);
    for (pan, tilt) in [(0.0f32, 0.0f32), (-10.0, -15.0), (8.0, -5.0)] {
        sim.set_pantilt(
            r,
            PtMotors {
                longitude: pan,
                latitude: tilt,
                ..PtMotors::default()
            },
        );
        run(&mut sim, 1.0);
        let cam = sim.camera(r, 320, 240);
        rend.render(&sim, r, &cam, &mut img);
        let want = cam
            .project_visible(HPoint3D::point(ball[0], ball[1], ball[2]))
            .expect("the ball is in front of the camera");
        // Off the optical axis a sphere's image is an ellipse whose centre lies a
        // little outward of its centre's projection (here up to ~0.6 px).
        let (x, y, n) = red_centroid(&img).expect("a red ball in view");
        assert!(n > 100, "only {n} red pixels");
        assert!(
            (x - want.x).abs() < 1.0 && (y - want.y).abs() < 1.0,
            "pan {pan} tilt {tilt}: red at optical ({x:.2}, {y:.2}), progeo projects the ball to ({:.2}, {:.2})",
            want.x,
            want.y
        );
        // Its apparent size matches the distance: the sphere's solid angle over
        // a pixel's (which shrinks as cos³ off the optical axis).
        let a = cam.rt * HPoint3D::point(ball[0], ball[1], ball[2]).to_vector();
        let d = (a.x * a.x + a.y * a.y + a.z * a.z).sqrt();
        let cone = std::f64::consts::TAU * (1.0 - (1.0 - (ball[2] / d).powi(2)).sqrt());
        let want = cone * cam.fdistx * cam.fdisty / (a.z / d).powi(3);
        assert!(
            (n as f64 / want - 1.0).abs() < 0.05,
            "{n} red pixels, expected about {want:.0}"
        );
    }
    // Walls above the horizon, floor below, the sky above the walls.
    sim.set_pantilt(r, PtMotors::default());
    run(&mut sim, 2.0);
    let cam = sim.camera(r, 320, 240);
    rend.render(&sim, r, &cam, &mut img);
    assert_eq!(img.pixel(5, 0), [235, 200, 170], "sky (BGR)");
    assert_ne!(img.pixel(5, 239), img.pixel(5, 0));
}

#[test]
fn pantilt_reaches_commanded_angles_within_limits() {
    let mut sim = Sim::new(World::new(), 1);
    let r = sim.add_robot("r", snappy(), 0.0, 0.0, 0.0);
    sim.set_pantilt(
        r,
        PtMotors {
            longitude: 60.0,
            latitude: -20.0,
            longitude_speed: 30.0,
            latitude_speed: 10.0,
            ..PtMotors::default()
        },
    );
    run(&mut sim, 1.0);
    let e = sim.pantilt_encoders(r);
    assert!(
        (e.pan_angle - 30.0).abs() < 1e-3 && (e.tilt_angle + 10.0).abs() < 1e-3,
        "{e:?}"
    );
    run(&mut sim, 2.0);
    let e = sim.pantilt_encoders(r);
    assert!(
        (e.pan_angle - 60.0).abs() < 1e-3 && (e.tilt_angle + 20.0).abs() < 1e-3,
        "{e:?}"
    );
    // Beyond the limits: it stops at them (pan ±159.13, tilt −46..+30).
    sim.set_pantilt(
        r,
        PtMotors {
            longitude: 400.0,
            latitude: -90.0,
            longitude_speed: 0.0, // the unit's maximum
            latitude_speed: 1e6,  // clamped to the maximum
            ..PtMotors::default()
        },
    );
    run(&mut sim, 3.0);
    let e = sim.pantilt_encoders(r);
    assert!(
        (e.pan_angle - 159.13).abs() < 1e-3 && (e.tilt_angle + 46.0).abs() < 1e-3,
        "{e:?}"
    );
    sim.set_pantilt(
        r,
        PtMotors {
            longitude: -400.0,
            latitude: 90.0,
            ..PtMotors::default()
        },
    );
    run(&mut sim, 3.0);
    let e = sim.pantilt_encoders(r);
    assert!(
        (e.pan_angle + 159.13).abs() < 1e-3 && (e.tilt_angle - 30.0).abs() < 1e-3,
        "{e:?}"
    );
}

#[test]
fn a_pushed_ball_rolls_and_stops() {
    let mut w = World::new();
    w.add_room([0.0, 0.0], [10000.0, 4000.0], 500.0, [200, 200, 200]);
    w.add_ball(BallSpec {
        pos: [2000.0, 2000.0],
        radius: 110.0,
        color: [255, 128, 0],
        friction: 300.0,
    });
    let mut sim = Sim::new(w, 1);
    let r = sim.add_robot("r", snappy(), 1000.0, 2000.0, 0.0);
    sim.set_motors(r, Motors { v: 500.0, w: 0.0 });
    run(&mut sim, 1.5);
    sim.set_motors(r, Motors::default());
    let b = &sim.balls[0];
    assert!(b.vel[0] > 300.0, "the ball was kicked: {:?}", b.vel);
    run(&mut sim, 10.0);
    let b = &sim.balls[0];
    assert_eq!(b.vel, [0.0, 0.0], "friction stopped it");
    assert!(b.pos[0] > 2500.0 && b.pos[0] < 9890.0, "{:?}", b.pos);
    assert!((b.pos[1] - 2000.0).abs() < 1e-6);
}

#[test]
fn the_asset_worlds_load() {
    for (name, walls) in [("simple", 5), ("building", 30), ("field", 4)] {
        let w = World::load(&root().join(format!("assets/worlds/{name}.world")))
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(
            w.segments.len() >= walls,
            "{name}: {} walls",
            w.segments.len()
        );
        assert!(!w.balls.is_empty() && !w.starts.is_empty(), "{name}");
    }
    // The building's floor plan: from the west end of the corridor the laser sees
    // the corridor walls 1 m away on both sides.
    let w = World::load(&root().join("assets/worlds/building.world")).unwrap();
    let mut sim = Sim::new(w, 1);
    let r = sim.add_robot("r", snappy(), 1500.0, 7500.0, 0.0);
    let mut laser = Laser::default();
    sim.laser(r, &mut laser);
    assert_eq!(laser.readings[0], 1000); // south corridor wall at y = 6500
    assert_eq!(laser.readings[179], 1000); // north corridor wall at y = 8500 (89 deg: 1000/sin 89°)
}

#[test]
fn world_file_errors_name_file_and_line() {
    let e = World::parse("room 0 0 10 10\nbox 1 2 3\n", Path::new("my.world")).unwrap_err();
    assert_eq!(e.to_string().split(": ").next(), Some("my.world:2"));
    assert!(e.message.contains("usage: box"), "{e}");
    let e = World::parse("floorplan missing.png 50\n", Path::new("my.world")).unwrap_err();
    assert!(
        e.to_string().starts_with("my.world:1: floorplan") && e.message.contains("cannot read"),
        "{e}"
    );
}

fn sim_conf(text: &str) -> anyhow::Result<Simulation> {
    let c = ComponentConf::from_text(Kind::Driver, "simulator", text).unwrap();
    Ok(Simulation::parse(&c)?)
}

#[test]
fn conf_lines_are_checked() {
    let e = sim_conf("robot a 0 0 0\nfly away\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("<inline>:2:") && e.contains("takes no `fly` line"),
        "{e}"
    );
    let e = sim_conf("provides laser robot9\n").unwrap_err().to_string();
    assert!(
        e.contains("<inline>:1") && e.contains("no robot called `robot9`"),
        "{e}"
    );
    let e = sim_conf("provides laser 180\n").unwrap_err().to_string();
    assert!(e.contains("<inline>:1"), "{e}");
    let e = sim_conf("provides colorA\nprovides colorA\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("<inline>:2") && e.contains("twice"), "{e}");
    let e = sim_conf("robot a NaN 0 0\n").unwrap_err().to_string();
    assert!(
        e.contains("<inline>:1") && e.contains("X (argument 2) is `NaN`, expected a number"),
        "{e}"
    );
    let e = sim_conf("speed fast\n").unwrap_err().to_string();
    assert!(e.contains("<inline>:1"), "{e}");
    let c = sim_conf(
        "robot one 100 200 90\nrobot two 300 400 0\nprovides laser 90 0.5\nprovides laser 360 2 two\nprovides varcolorB 64 48 two\n",
    )
    .unwrap();
    assert_eq!(c.provides[0].laser.as_deref(), Some("laser"));
    assert_eq!(c.provides[1].laser.as_deref(), Some("laser.two"));
    assert_eq!(
        c.provides[1].cameras,
        vec![("varcolorB.two".to_string(), 64, 48)]
    );
    assert_eq!(c.sim.robots[0].model.laser_count, 90);
    assert_eq!(c.sim.robots[1].model.laser_count, 360);
    assert_eq!(
        (c.sim.robots[1].pose.x, c.sim.robots[1].pose.y),
        (300.0, 400.0)
    );
}

fn start(body: &str) -> Arc<Runtime> {
    start_conf(&format!(
        "driver simulator\nworld {}\n{body}\nend_driver\nload_driver simulator\n",
        world_path("simple.world")
    ))
}

/// The balls as they roll are in the name space (`world.balls`): a robot
/// driving into simple.world's red ball pushes it east.
#[test]
fn the_driver_publishes_the_balls_as_they_roll() {
    let rt = start("robot robot1 3900 1200 0\nprovides encoders\nprovides motors\nspeed 4\n");
    let live = world::balls(&rt.names).expect("world.balls");
    let balls = live.load();
    assert_eq!(balls.len(), 1, "simple.world has one ball");
    assert_eq!((balls[0].pos, balls[0].radius), ([4500.0, 1200.0], 110.0));
    assert_eq!(balls[0].color, [220, 20, 20]);
    let motors: Arc<Interface<Motors>> = rt.interfaces.get("motors").unwrap();
    eventually("the ball to roll east", || {
        let _ = motors.publish(Motors { v: 400.0, w: 0.0 });
        live.load()[0].pos[0] > 4700.0
    });
    rt.shutdown();
}

#[test]
fn the_driver_loads_from_a_conf_and_publishes() {
    let rt = start(
        "robot robot1 1000 2000 0\nrobot robot2 2000 3000 0\nprovides encoders\nprovides motors\n\
         provides laser 180 1\nprovides colorA\nprovides laser robot2\nprovides encoders robot2\nspeed 4\n",
    );
    let enc: Arc<Interface<Encoders>> = rt.interfaces.get("encoders").unwrap();
    let laser: Arc<Interface<Laser>> = rt.interfaces.get("laser").unwrap();
    assert!(rt.interfaces.get::<Laser>("laser.robot2").is_ok());
    // The static world is in the name space for schemas that draw or plan over it.
    let world = world::map(&rt.names).expect("world.map");
    assert!(world.segments.len() >= 5, "the room and its partition");
    assert!(rt.interfaces.get::<Encoders>("encoders.robot2").is_ok());
    eventually("encoders published a few times", || enc.clock() > 3);
    let e = enc.read();
    assert_eq!((e.x, e.y), (1000.0, 2000.0));
    // Nobody uses the laser or the camera: they are not computed.
    assert_eq!(laser.clock(), 0);
    assert_eq!(rt.interfaces.get::<Image>("colorA").unwrap().clock(), 0);
    rt.run("laser").unwrap();
    eventually("a laser scan", || laser.clock() > 0);
    let l = laser.read();
    assert_eq!(l.readings.len(), 180);
    // simple.world is a 6 m x 4 m room: straight ahead, the east wall.
    assert_eq!(l.readings[90], 6000 - 1019);
    drop(l);
    // Driving: the encoders follow the motors.
    let motors: Arc<Interface<Motors>> = rt.interfaces.get("motors").unwrap();
    eventually("the robot moves east", || {
        motors.publish(Motors { v: 400.0, w: 0.0 }).unwrap();
        std::thread::sleep(Duration::from_millis(5));
        enc.read().x > 1100.0
    });
    rt.shutdown();
    assert_eq!(
        motors.read().value,
        Motors::default(),
        "terminate zeroes the motors"
    );
}

#[test]
fn a_stale_motors_command_stops_the_robot() {
    let rt = start(
        "robot robot1 1000 2000 0\nprovides encoders\nprovides motors\nmotors_timeout 100\naccel 100000 1000\n",
    );
    let enc: Arc<Interface<Encoders>> = rt.interfaces.get("encoders").unwrap();
    let motors: Arc<Interface<Motors>> = rt.interfaces.get("motors").unwrap();
    // Commands until it moves (the driver may not get the CPU at once), then
    // none: the robot stops by itself, well before the wall 4.7 m away.
    eventually("the robot moves", || {
        motors.publish(Motors { v: 300.0, w: 0.0 }).unwrap();
        std::thread::sleep(Duration::from_millis(5));
        enc.read().x > 1000.5
    });
    let mut last = (enc.read().x, enc.clock());
    eventually("the robot stops", || {
        let (x, c) = (enc.read().x, enc.clock());
        if c >= last.1 + 3 {
            let stopped = x == last.0;
            last = (x, c);
            stopped
        } else {
            false
        }
    });
    let x = enc.read().x;
    assert!(x < 4000.0, "it kept driving on a stale command: x = {x}");
    rt.shutdown();
}

#[test]
fn stepped_mode_advances_per_command() {
    let rt = start(
        "robot robot1 1000 2000 0\nprovides encoders\nprovides motors\nstepped 100\naccel 1000000 1000000\nperiod encoders 10\n",
    );
    let enc: Arc<Interface<Encoders>> = rt.interfaces.get("encoders").unwrap();
    let motors: Arc<Interface<Motors>> = rt.interfaces.get("motors").unwrap();
    eventually("first encoders", || enc.clock() >= 1);
    assert_eq!(enc.read().x, 1000.0);
    for k in 1..=3 {
        motors.publish(Motors { v: 500.0, w: 0.0 }).unwrap();
        // Each command is 100 ms of simulated time: exactly 50 mm more.
        let want = 1000.0 + 50.0 * k as f32;
        eventually("one more step", || (enc.read().x - want).abs() < 0.01);
    }
    rt.shutdown();
}

#[test]
fn the_example_conf_runs() {
    let conf =
        Conf::load(&root().join("examples/simulator.conf")).unwrap_or_else(|e| panic!("{e}"));
    let rt = jderobot::loader::start(&conf).unwrap_or_else(|e| panic!("{e}"));
    for name in [
        "encoders",
        "motors",
        "laser",
        "sonars",
        "bumpers",
        "colorA",
        "pantiltencoders",
        "pantiltmotors",
        "encoders.robot2",
        "motors.robot2",
        "laser.robot2",
    ] {
        assert!(
            rt.interfaces.contains(name),
            "{name} missing: {:?}",
            rt.interfaces.names()
        );
    }
    let img: Arc<Interface<Image>> = rt.interfaces.get("colorA").unwrap();
    rt.run("colorA").unwrap();
    eventually("a camera frame", || img.clock() > 0);
    let frame = img.read();
    assert_eq!(
        (frame.width, frame.height, frame.data.len()),
        (320, 240, 320 * 240 * 3)
    );
    drop(frame);
    rt.shutdown();
}

#[test]
fn the_imu_reads_heading_turn_rate_and_accelerations_in_si_units() {
    let mut sim = Sim::new(room(), 1);
    let r = sim.add_robot("r", RobotModel::default(), 2000.0, 2000.0, 90.0);
    let at_rest = sim.imu(r);
    let half = 45f32.to_radians();
    assert!((at_rest.qz - half.sin()).abs() < 1e-6 && (at_rest.qw - half.cos()).abs() < 1e-6);
    assert_eq!((at_rest.ax, at_rest.ay, at_rest.wz), (0.0, 0.0, 0.0));
    assert_eq!(at_rest.az, 9.80665, "gravity, as an accelerometer reads it");
    // Speeding up (300 mm/s² is the model's limit): a forward acceleration.
    sim.set_motors(r, Motors { v: 500.0, w: 0.0 });
    sim.step(DT);
    assert!((sim.imu(r).ax - 0.3).abs() < 1e-4, "{:?}", sim.imu(r));
    // A steady turn of 20 deg/s at 200 mm/s: ω in rad/s, centripetal v·ω to the left.
    let mut sim = Sim::new(room(), 1);
    let r = sim.add_robot("r", snappy(), 2000.0, 2000.0, 0.0);
    sim.set_motors(r, Motors { v: 200.0, w: 20.0 });
    run(&mut sim, 1.0);
    let imu = sim.imu(r);
    let w = 20f32.to_radians();
    assert!((imu.wz - w).abs() < 1e-5, "{imu:?}");
    assert!((imu.ay - 0.2 * w).abs() < 1e-5, "{imu:?}");
    assert!(imu.ax.abs() < 1e-6, "{imu:?}");
    // The heading: 20° after one second, from the true pose (no odometry noise).
    let (_, _, yaw) = imu.euler();
    assert!((yaw.to_degrees() - 20.0).abs() < 0.01, "{yaw}");
}
