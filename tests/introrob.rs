//! introrob's behaviours against the simulator, headless and deterministic: the
//! controller ([`Brain`]) is driven in a loop against a stepped [`Sim`] (sensors
//! from the Sim → controller → motors → `Sim::step`), plus one run through the
//! real runtime and a conf file.
#![cfg(all(feature = "introrob", feature = "simulator"))]

use std::{
    path::{Path, PathBuf},
    sync::Arc,
    time::{Duration, Instant},
};

use jderobot::{
    conf::Conf,
    drivers::simulator::{RobotModel, Sim},
    interfaces::{Bumpers, Encoders, Laser, Motors, Mount, Sonars},
    schemas::introrob::{
        Behaviour, Brain, Dashboard, Inputs,
        gpp::{self, GridMap, PlanParams},
        navigation::{Robot, absolute_to_relative, relative_to_absolute},
    },
    world::World,
};

fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/worlds")
}

fn world(name: &str) -> World {
    World::load(&assets().join(name)).expect("world loads")
}

/// A simulation with one Pioneer and introrob's brain on it.
struct Bench {
    sim: Sim,
    brain: Brain,
    laser: Laser,
    sonars: Sonars,
    bumpers: Bumpers,
    /// Every robot position, once per controller iteration.
    track: Vec<[f64; 2]>,
    /// Whether the robot ever touched anything.
    collided: bool,
    /// The shortest laser reading seen, mm.
    min_laser: i32,
}

impl Bench {
    fn new(w: World, pose: (f64, f64, f64), max_v: f32, max_w: f32) -> Bench {
        let mut sim = Sim::new(w.clone(), 1);
        sim.add_robot("robot1", RobotModel::default(), pose.0, pose.1, pose.2);
        let shared = Dashboard::new(Some(Arc::new(w)), max_v, max_w);
        Bench {
            sim,
            brain: Brain::new(shared),
            laser: Laser::default(),
            sonars: Sonars::default(),
            bumpers: Bumpers::default(),
            track: Vec::new(),
            collided: false,
            min_laser: i32::MAX,
        }
    }

    fn dashboard(&self) -> &Dashboard {
        &self.brain.dashboard
    }

    fn pose(&self) -> Encoders {
        self.sim.encoders(0)
    }

    /// One 100 ms controller iteration: sense, decide, act, simulate 10 × 10 ms.
    fn iterate(&mut self) -> Motors {
        self.sim.laser(0, &mut self.laser);
        self.sim.sonars(0, &mut self.sonars);
        self.sim.bumpers(0, &mut self.bumpers);
        self.min_laser = self
            .min_laser
            .min(*self.laser.readings.iter().min().unwrap());
        let input = Inputs {
            pose: self.pose(),
            laser: &self.laser,
            sonars: Some(&self.sonars),
            bumpers: Some(&self.bumpers),
            image: None,
            time: self.sim.time,
        };
        let m = self.brain.step(&input);
        self.sim.set_motors(0, m);
        for _ in 0..10 {
            self.sim.step(0.01);
            let r = &self.sim.robots[0];
            if r.stalled || r.bumpers.iter().any(|&b| b != 0) {
                self.collided = true;
            }
        }
        let r = &self.sim.robots[0];
        self.track.push([r.pose.x, r.pose.y]);
        m
    }

    /// Iterates until `done` or `seconds` of simulated time; returns whether done.
    fn run_until(&mut self, seconds: f64, mut done: impl FnMut(&Bench) -> bool) -> bool {
        let end = self.sim.time + seconds;
        while self.sim.time < end {
            self.iterate();
            if done(self) {
                return true;
            }
        }
        false
    }

    fn distance_to(&self, p: [f32; 2]) -> f32 {
        let r = &self.sim.robots[0].pose;
        ((r.x as f32 - p[0]).powi(2) + (r.y as f32 - p[1]).powi(2)).sqrt()
    }
}

#[test]
fn vff_crosses_the_simple_room_without_touching_anything() {
    // From the south-west corner, heading north, to the east side of the room: the
    // straight line passes the tip of the partition at x = 3000.
    let target = [5000.0, 2200.0];
    let mut b = Bench::new(world("simple.world"), (1000.0, 1000.0, 90.0), 400.0, 40.0);
    b.dashboard().set_target(Some(target));
    b.dashboard().set_behaviour(Behaviour::Vff);
    let reached = b.run_until(120.0, |b| {
        b.dashboard().view.lock().status == "vff: target reached"
    });
    let last = b.track.last().copied().unwrap();
    assert!(
        reached,
        "VFF did not reach {target:?} in 120 s; ended at {last:?}, status {:?}",
        b.dashboard().view.lock().status
    );
    assert!(
        b.distance_to(target) < 200.0,
        "ended {:.0} mm away",
        b.distance_to(target)
    );
    assert!(!b.collided, "the robot touched something");
    assert!(
        b.min_laser > 250 - 19,
        "the laser saw an obstacle within the robot's radius: {} mm",
        b.min_laser
    );
    // Once there it stays there.
    let m = b.iterate();
    assert_eq!((m.v, m.w), (0.0, 0.0));
    eprintln!(
        "vff: reached in {:.1} s, min laser {} mm",
        b.sim.time, b.min_laser
    );
}

#[test]
fn vff_targets_elsewhere_in_the_room() {
    // A few more targets from other starts, each reached without contact.
    for (start, target) in [
        ((5000.0, 1000.0, 180.0), [1200.0, 2300.0]),
        ((2000.0, 3000.0, 0.0), [4000.0, 600.0]),
        ((1000.0, 1000.0, 0.0), [2000.0, 3300.0]),
    ] {
        let mut b = Bench::new(world("simple.world"), start, 400.0, 40.0);
        b.dashboard().set_target(Some(target));
        b.dashboard().set_behaviour(Behaviour::Vff);
        let reached = b.run_until(120.0, |b| {
            b.dashboard().view.lock().status == "vff: target reached"
        });
        assert!(
            reached,
            "{start:?} → {target:?}: not reached; ended at {:?}",
            b.track.last()
        );
        assert!(!b.collided, "{start:?} → {target:?}: touched something");
    }
}

#[test]
fn gpp_plans_through_doors_and_the_robot_follows_without_collision() {
    // From the first south room, through its door onto the corridor, and through a
    // north door into the room opposite.
    let goal = [2500.0, 12000.0];
    let mut b = Bench::new(world("building.world"), (3000.0, 3000.0, 90.0), 400.0, 40.0);
    b.dashboard().set_target(Some(goal));
    b.dashboard().set_behaviour(Behaviour::Gpp);
    let reached = b.run_until(240.0, |b| {
        b.dashboard().view.lock().status == "gpp: goal reached"
    });
    let status = b.dashboard().view.lock().status.clone();
    assert!(
        reached,
        "GPP did not reach {goal:?}; ended at {:?}, status {status:?}",
        b.track.last()
    );
    assert!(b.distance_to(goal) < 200.0);
    assert!(!b.collided, "the robot touched something");
    // It went through the south-west door (x 2000..3000 at the corridor's south
    // wall, y 6400) and a north door (x 3000..4000 at y 8600).
    let crossing = |y: f64| {
        b.track
            .windows(2)
            .find(|w| (w[0][1] - y) * (w[1][1] - y) <= 0.0)
            .map(|w| w[0][0])
    };
    let south = crossing(6400.0).expect("crossed the corridor's south wall");
    let north = crossing(8600.0).expect("crossed the corridor's north wall");
    assert!(
        (2000.0..3000.0).contains(&south),
        "south crossing at x = {south:.0}"
    );
    assert!(
        (3000.0..4000.0).contains(&north),
        "north crossing at x = {north:.0}"
    );
    eprintln!(
        "gpp: reached in {:.1} s, min laser {} mm",
        b.sim.time, b.min_laser
    );
}

#[test]
fn gpp_through_the_door_between_two_south_rooms() {
    // The internal door between the two south-west rooms (x = 5000, y 2500..3500).
    let goal = [7500.0, 3000.0];
    let mut b = Bench::new(world("building.world"), (3000.0, 3000.0, 90.0), 400.0, 40.0);
    b.dashboard().set_target(Some(goal));
    b.dashboard().set_behaviour(Behaviour::Gpp);
    let reached = b.run_until(120.0, |b| {
        b.dashboard().view.lock().status == "gpp: goal reached"
    });
    assert!(reached, "not reached; ended at {:?}", b.track.last());
    assert!(!b.collided);
    let path = b.dashboard().view.lock().path.clone();
    assert!(path.len() > 10);
}

#[test]
fn gpp_reports_unreachable_and_blocked_goals() {
    let w = world("building.world");
    let map = GridMap::from_world(&w, 50.0);
    let p = PlanParams::default();
    // Inside a wall.
    let e = gpp::plan(&map, [3000.0, 3000.0], [5000.0, 1000.0], &p).unwrap_err();
    assert!(e.to_string().contains("too close"), "{e}");
    // Outside the map.
    let e = gpp::plan(&map, [3000.0, 3000.0], [90000.0, 0.0], &p).unwrap_err();
    assert!(e.to_string().contains("outside"), "{e}");
    // Outside the building (reachable cells only around it): unreachable.
    let e = gpp::plan(&map, [3000.0, 3000.0], [-700.0, -700.0], &p).unwrap_err();
    assert!(e.to_string().contains("cannot reach"), "{e}");
    // An empty world has no map.
    let e = gpp::plan(
        &GridMap::from_world(&World::new(), 50.0),
        [0.0; 2],
        [1.0; 2],
        &p,
    )
    .unwrap_err();
    assert!(e.to_string().contains("empty"), "{e}");
    // A good plan keeps its clearance: every point is at least the radius from walls.
    let path = gpp::plan(&map, [3000.0, 3000.0], [2500.0, 12000.0], &p).unwrap();
    for q in &path[1..path.len() - 1] {
        assert!(map.clearance_at(*q) >= 250.0, "{q:?} too close to a wall");
    }
}

#[test]
fn teleoperation_moves_the_robot_as_commanded() {
    let mut b = Bench::new(world("simple.world"), (1000.0, 2000.0, 0.0), 500.0, 30.0);
    b.dashboard().set_behaviour(Behaviour::Teleop);
    // 300 mm/s ahead for 3 s: about 900 mm less the acceleration ramp (300 mm/s²).
    b.dashboard().set_teleop(300.0, 0.0);
    b.run_until(3.0, |_| false);
    let p = b.pose();
    assert!((p.x - 1000.0 - 825.0).abs() < 60.0, "x = {}", p.x);
    assert!((p.y - 2000.0).abs() < 5.0, "y = {}", p.y);
    // Turn in place at 30 deg/s for 3 s: about 90 degrees less the ramp.
    b.dashboard().set_teleop(0.0, 30.0);
    b.run_until(3.0, |_| false);
    let p2 = b.pose();
    let turned = (p2.theta - p.theta).to_degrees().rem_euclid(360.0);
    assert!((turned - 85.0).abs() < 8.0, "turned {turned}");
    // Commands beyond the maxima are clamped (500 mm/s, 30 deg/s).
    b.dashboard().set_teleop(5000.0, -900.0);
    assert_eq!(*b.dashboard().teleop.lock(), Motors { v: 500.0, w: -30.0 });
    // Stop: the robot comes to rest.
    b.dashboard().set_behaviour(Behaviour::Stop);
    b.run_until(3.0, |_| false);
    let a = b.pose();
    b.run_until(1.0, |_| false);
    let z = b.pose();
    assert!(
        (a.x - z.x).abs() < 1.0 && (a.y - z.y).abs() < 1.0,
        "still moving"
    );
    assert_eq!(b.sim.robots[0].v, 0.0);
}

#[test]
fn your_code_sample_wanders_safely() {
    let mut b = Bench::new(world("simple.world"), (1000.0, 1000.0, 0.0), 500.0, 30.0);
    b.dashboard().set_behaviour(Behaviour::YourCode);
    b.run_until(60.0, |_| false);
    assert!(!b.collided, "the sample touched something");
    let odometer = b.sim.robots[0].odometer;
    assert!(odometer > 2000.0, "the sample barely moved: {odometer} mm");
    // It drew its two sample segments.
    assert_eq!(b.dashboard().view.lock().drawings.len(), 2);
}

#[test]
fn absolute_relative_helpers_follow_4_3() {
    // A robot at (1000, 500) heading 90°: a point 1 m ahead is (1000, 1500).
    let r = Encoders::from_pose(1000.0, 500.0, std::f32::consts::FRAC_PI_2).robot();
    let a = relative_to_absolute(&r, [1000.0, 0.0]);
    assert!(
        (a[0] - 1000.0).abs() < 1e-3 && (a[1] - 1500.0).abs() < 1e-3,
        "{a:?}"
    );
    // A point to the robot's left (x−) is at relative y+.
    let rel = absolute_to_relative(&r, [0.0, 500.0]);
    assert!(
        rel[0].abs() < 1e-3 && (rel[1] - 1000.0).abs() < 1e-3,
        "{rel:?}"
    );
    for p in [[12.0, -7.0], [-3000.0, 250.0]] {
        let q = absolute_to_relative(&r, relative_to_absolute(&r, p));
        assert!((q[0] - p[0]).abs() < 1e-2 && (q[1] - p[1]).abs() < 1e-2);
    }
    let robot = Robot {
        robot: r,
        laser: Laser {
            readings: vec![1000; 180],
            mount: Mount::PIONEER_LASER,
            ..Laser::default()
        },
        ..Robot::default()
    };
    assert_eq!(robot.laser_angle(90), 0.0);
    assert_eq!(robot.min_laser(-30.0, 30.0), Some(1000.0));
    let p = robot.laser_point(90).unwrap();
    assert!((p[0] - 1019.0).abs() < 1e-3 && p[1].abs() < 1e-3);
}

fn write_conf(dir: &Path, name: &str, text: &str) -> PathBuf {
    let f = dir.join(name);
    std::fs::write(&f, text).unwrap();
    f
}

#[test]
fn introrob_through_the_runtime_moves_toward_its_target() {
    let dir = tempfile::tempdir().unwrap();
    let world = assets().join("simple.world");
    let conf = write_conf(
        dir.path(),
        "introrob.conf",
        &format!(
            "driver simulator\nworld {}\nrobot robot1 1000 1000 90\nprovides encoders\n\
             provides motors\nprovides laser 180 1\nprovides sonars\nprovides bumpers\n\
             speed 4\nend_driver\n\
             schema introrob\nbehaviour vff\ntarget 5000 2200\nmax_v 400\nmax_w 40\ncycle 25\nend_schema\n\
             load_driver simulator\nload_schema introrob\nrun introrob\n",
            world.display()
        ),
    );
    let conf = Conf::load(&conf).expect("conf parses");
    let rt = jderobot::loader::start(&conf).expect("runtime starts");
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let target = [5000.0f32, 2200.0];
    let d = |e: Encoders| ((e.x - target[0]).powi(2) + (e.y - target[1]).powi(2)).sqrt();
    let d0 = d(enc.read().value);
    let t = Instant::now();
    let mut best = d0;
    while t.elapsed() < Duration::from_secs(20) && best > d0 - 1000.0 {
        std::thread::sleep(Duration::from_millis(100));
        best = best.min(d(enc.read().value));
    }
    // The simulator's world came from the simulator's section (no `world` line).
    let shared = rt
        .names
        .import::<Dashboard>("introrob", "state")
        .expect("introrob exports its state");
    assert!(
        shared.world.is_some(),
        "introrob found the simulator's world"
    );
    // The name space changes the behaviour: stop.
    *rt.names
        .import::<parking_lot::Mutex<Behaviour>>("introrob", "behaviour")
        .unwrap()
        .lock() = Behaviour::Stop;
    std::thread::sleep(Duration::from_millis(300));
    let status = shared.view.lock().status.clone();
    rt.shutdown();
    assert!(
        best <= d0 - 1000.0,
        "the robot did not get 1 m closer to the target: {d0:.0} → {best:.0} mm"
    );
    assert_eq!(status, "stopped");
}

/// A robot without a laser (a NAO): `laser none`, and VFF still heads for its
/// target (it sees no laser obstacles).
#[test]
fn laser_none_drives_a_robot_without_a_laser() {
    let dir = tempfile::tempdir().unwrap();
    let conf = write_conf(
        dir.path(),
        "nolaser.conf",
        "driver simulator\nrobot robot1 1000 1000 0\nprovides encoders\nprovides motors\n\
         end_driver\nschema introrob\nbehaviour vff\ntarget 3000 1000\nlaser none\n\
         sonars none\nbumpers none\ncamera none\nend_schema\n\
         load_driver simulator\nload_schema introrob\nrun introrob\n",
    );
    let conf = Conf::load(&conf).expect("conf parses");
    let rt = jderobot::loader::start(&conf).expect("runtime starts without a laser");
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let t = Instant::now();
    while t.elapsed() < Duration::from_secs(20) && enc.read().x < 2000.0 {
        std::thread::sleep(Duration::from_millis(100));
    }
    let x = enc.read().x;
    rt.shutdown();
    assert!(
        x >= 2000.0,
        "the robot did not head for its target: x = {x:.0} mm"
    );
}

#[test]
fn conf_errors_name_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let world = assets().join("simple.world");
    for (line, expect) in [
        ("behaviour fly", "is `fly`, expected one of teleop"),
        ("target 1 two", "Y (argument 2) is `two`, expected a number"),
        ("max_v -3", "between 1 and 1000 mm/s"),
        ("max_v 4000000000000", "between 1 and 1000 mm/s"),
        ("wibble 3", "takes no `wibble` line"),
        ("world nowhere.world", "world"),
    ] {
        let conf = write_conf(
            dir.path(),
            "bad.conf",
            &format!(
                "driver simulator\nworld {}\nprovides encoders\nprovides motors\nprovides laser\n\
                 end_driver\nschema introrob\n{line}\nend_schema\nload_driver simulator\nload_schema introrob\n",
                world.display()
            ),
        );
        let conf = Conf::load(&conf).expect("conf parses");
        let e = match jderobot::loader::start(&conf) {
            Ok(rt) => {
                rt.shutdown();
                panic!("`{line}` was accepted")
            }
            Err(e) => e.to_string(),
        };
        assert!(e.contains("bad.conf:8"), "`{line}`: {e}");
        assert!(e.contains(expect), "`{line}`: {e}");
    }
    // Without a laser, introrob says what it needs.
    let conf = write_conf(
        dir.path(),
        "nolaser.conf",
        "driver simulator\nprovides encoders\nprovides motors\nend_driver\n\
         load_driver simulator\nload_schema introrob\n",
    );
    let e = jderobot::loader::start(&Conf::load(&conf).unwrap())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("laser"), "{e}");
}

#[test]
fn shell_init_with_another_conf_changes_behaviour_and_target() {
    // The shell's `zoom introrob` + `init FILE` re-creates introrob from FILE's
    // section; the panel's and the name space's state carry the new values.
    let dir = tempfile::tempdir().unwrap();
    let world = assets().join("simple.world");
    let main = write_conf(
        dir.path(),
        "main.conf",
        &format!(
            "driver simulator\nworld {}\nrobot robot1 1000 1000 90\nprovides encoders\n\
             provides motors\nprovides laser\nend_driver\n\
             load_driver simulator\nload_schema introrob\nrun introrob\n",
            world.display()
        ),
    );
    let rt = jderobot::loader::start(&Conf::load(&main).unwrap()).expect("starts");
    let shared = rt.names.import::<Dashboard>("introrob", "state").unwrap();
    assert_eq!(*shared.behaviour.lock(), Behaviour::Teleop);
    let go = write_conf(
        dir.path(),
        "go.conf",
        "schema introrob\nbehaviour gpp\ntarget 5000 3000\nend_schema\n",
    );
    jderobot::loader::reinit(&rt, "introrob", Some(&go)).expect("init");
    let ok = (0..100).any(|_| {
        std::thread::sleep(Duration::from_millis(50));
        shared.view.lock().status.starts_with("gpp:")
    });
    let status = shared.view.lock().status.clone();
    rt.shutdown();
    assert_eq!(*shared.behaviour.lock(), Behaviour::Gpp);
    assert_eq!(*shared.target.lock(), Some([5000.0, 3000.0]));
    assert!(
        ok,
        "the re-created schema did not report into the shared state: {status:?}"
    );
}

#[test]
fn garbage_inputs_do_not_panic() {
    // NaN and infinite poses, empty or odd scans, absurd maxima and targets: the
    // brain answers with finite commands.
    let w = world("simple.world");
    for (max_v, max_w) in [(400.0, 40.0), (-1.0, f32::NAN), (f32::INFINITY, 0.0)] {
        let shared = Dashboard::new(Some(Arc::new(w.clone())), max_v, max_w);
        let mut brain = Brain::new(shared.clone());
        let scans = [
            Laser::default(),
            Laser {
                readings: vec![-5, 0, i32::MAX, 100],
                resolution: 0.0,
                ..Laser::default()
            },
            Laser {
                readings: vec![10; 720],
                resolution: 4.0,
                ..Laser::default()
            },
        ];
        let poses = [
            Encoders::from_pose(f32::NAN, 0.0, 0.0),
            Encoders::from_pose(1e30, -1e30, f32::INFINITY),
            Encoders::from_pose(1000.0, 1000.0, 1.0),
        ];
        let targets = [
            None,
            Some([f32::NAN, 0.0]),
            Some([1e30, 5.0]),
            Some([3000.0, 2000.0]),
        ];
        for b in Behaviour::ALL {
            shared.set_behaviour(b);
            shared.set_teleop(f32::NAN, 1e9);
            for t in targets {
                shared.set_target(t);
                for laser in &scans {
                    for pose in poses {
                        let m = brain.step(&Inputs {
                            pose,
                            laser,
                            sonars: None,
                            bumpers: None,
                            image: None,
                            time: 0.0,
                        });
                        assert!(m.v.is_finite() && m.w.is_finite(), "{b} {t:?} {m:?}");
                    }
                }
            }
        }
    }
}

/// Without a map (no `world` line and nothing exported as `world.map`, or `world
/// none`), gpp stands still and says it needs one; the other behaviours still run.
#[test]
fn without_a_map_gpp_says_it_needs_one() {
    let dashboard = Dashboard::new(None, 500.0, 30.0);
    let mut brain = Brain::new(dashboard.clone());
    dashboard.set_target(Some([2000.0, 0.0]));
    dashboard.set_behaviour(Behaviour::Gpp);
    let laser = Laser {
        readings: vec![8000; 180],
        resolution: 1.0,
        ..Laser::default()
    };
    let input = Inputs {
        pose: Encoders::default(),
        laser: &laser,
        sonars: None,
        bumpers: None,
        image: None,
        time: 0.0,
    };
    let m = brain.step(&input);
    assert_eq!((m.v, m.w), (0.0, 0.0), "gpp without a map stands still");
    let status = dashboard.view.lock().status.clone();
    assert!(
        status.contains("needs a map") && status.contains("world.map"),
        "{status}"
    );
    dashboard.set_behaviour(Behaviour::Vff);
    let m = brain.step(&input);
    assert!(m.v > 0.0, "vff needs no map: {m:?}");
}
