//! The Robotics Academy's three classic worlds (flat, obstacle_circuit,
//! line_circuit) and the scores the simulator keeps in them (floor swept,
//! targets reached, laps of the painted line), through the public `Sim` API, the
//! simulator's conf lines and the driver. Robots are driven by small Rust
//! controllers that use the true pose, in simulated time: each test takes seconds.
#![cfg(feature = "simulator")]

use crate::common;

use common::{eventually, root, start_conf, world_path};
use std::path::Path;

use jderobot::{
    ComponentConf, Conf,
    conf::Kind,
    drivers::simulator::{Renderer, Sim, Simulation},
    interfaces::{Image, Laser, Motors},
    world::{self, Point2, Score, World, closest_on, closest_on_segment},
};

const DT: f64 = 0.01;

fn load(name: &str) -> World {
    World::load(&root().join(format!("assets/worlds/{name}.world")))
        .unwrap_or_else(|e| panic!("{e}"))
}

/// The simulation of `lines` (a simulator section's body) in world `name`.
fn simulation(name: &str, lines: &str) -> Result<Simulation, String> {
    let text = format!("world {}\n{lines}", world_path(&format!("{name}.world")));
    let c =
        ComponentConf::from_text(Kind::Driver, "simulator", &text).map_err(|e| e.to_string())?;
    Simulation::parse(&c).map_err(|e| e.to_string())
}

/// Whether a disc of `r` at `p` is clear of every wall and box face, and not
/// inside a box.
fn free(w: &World, p: Point2, r: f64) -> bool {
    let clear = w.segments.iter().all(|s| {
        let q = closest_on_segment(p, s);
        (q[0] - p[0]).hypot(q[1] - p[1]) > r
    });
    let inside = w.boxes.iter().any(|b| {
        let c = b.corners();
        (0..4).all(|k| {
            let (a, e) = (c[k], c[(k + 1) % 4]);
            (e[0] - a[0]) * (p[1] - a[1]) - (e[1] - a[1]) * (p[0] - a[0]) > 0.0
        })
    });
    clear && !inside
}

#[test]
fn the_academy_worlds_parse_and_their_starts_are_free() {
    for name in ["flat", "obstacle_circuit", "line_circuit"] {
        let w = load(name);
        assert!(!w.starts.is_empty(), "{name}: no start");
        for s in &w.starts {
            assert!(
                free(&w, [s.x, s.y], 250.0),
                "{name}: start {s:?} is not free"
            );
        }
    }
    let flat = load("flat");
    assert!(flat.boxes.len() >= 10, "furniture: {}", flat.boxes.len());
    let course = load("obstacle_circuit");
    assert!((6..=10).contains(&course.targets.len()));
    for t in &course.targets {
        assert!(free(&course, *t, 250.0), "target {t:?} is not free");
    }
    let line = load("line_circuit");
    let paint = line.paint.iter().find(|p| p.closed).expect("a closed line");
    assert!((30.0..=50.0).contains(&paint.width) && paint.color == [220, 20, 20]);
    let s = &line.starts[0];
    assert!(paint.distance([s.x, s.y]) < 1.0, "the start is on the line");
    assert!(
        line.segments.len() == 4,
        "only the hall's walls: paint is no obstacle"
    );
}

/// Red pixels (the renderer writes BGR) in the bottom half, and their mean column.
fn red_below(img: &Image) -> (usize, f64) {
    let (mut n, mut cols) = (0, 0.0);
    for row in img.height / 2..img.height {
        for col in 0..img.width {
            let [b, g, r] = img.pixel(col, row);
            if r > 150 && g < 60 && b < 60 {
                n += 1;
                cols += col as f64;
            }
        }
    }
    (n, cols / n.max(1) as f64)
}

#[test]
fn the_forward_camera_sees_the_line_ahead() {
    let s = simulation("line_circuit", "provides colorA\ncamera_tilt -20\n").unwrap();
    let sim = &s.sim;
    assert_eq!(
        sim.pantilt_encoders(0).tilt_angle,
        -20.0,
        "it starts tilted"
    );
    let mut img = Image::new(320, 240);
    Renderer::new().render(sim, 0, &sim.camera(0, 320, 240), &mut img);
    let (n, col) = red_below(&img);
    // The line runs straight ahead from under the robot: a strip up the middle.
    assert!(n > 500, "{n} red pixels in the bottom half");
    assert!((col - 160.0).abs() < 5.0, "the line's mean column: {col}");
    // Level, the camera still sees it farther off, narrower.
    let level = simulation("line_circuit", "provides colorA\n").unwrap();
    Renderer::new().render(&level.sim, 0, &level.sim.camera(0, 320, 240), &mut img);
    let (m, _) = red_below(&img);
    assert!(m > 50 && m < n, "level: {m} red pixels, tilted: {n}");
    // Turned away from the line: no red.
    let away = simulation(
        "line_circuit",
        "robot r 6000 3000 90\nprovides colorA\ncamera_tilt -20\n",
    )
    .unwrap();
    Renderer::new().render(&away.sim, 0, &away.sim.camera(0, 320, 240), &mut img);
    assert_eq!(red_below(&img).0, 0);
}

/// The front of a scan: the nearest reading within ±`half` degrees, mm.
fn front(l: &Laser, half: f64) -> f64 {
    l.readings
        .iter()
        .enumerate()
        .filter(|(i, _)| (l.start as f64 + *i as f64 / l.resolution as f64).abs() <= half)
        .map(|(_, &d)| d as f64)
        .fold(f64::INFINITY, f64::min)
}

fn swept(sim: &Sim) -> (usize, usize) {
    match sim.score() {
        Some(Score::Swept(s)) => (s.swept, s.cells),
        other => panic!("no swept score: {other:?}"),
    }
}

#[test]
fn the_swept_share_grows_as_the_robot_drives_and_never_passes_the_floor() {
    let mut s = simulation("flat", "score swept\n").unwrap();
    let sim = &mut s.sim;
    let (mine, cells) = swept(sim);
    // Standing still: only its own footprint (π·250² over 200 mm cells ≈ 4.9).
    assert!((3..=7).contains(&mine), "footprint: {mine} cells");
    assert!(
        (1000..1750).contains(&cells),
        "the flat's floor: {cells} cells"
    );
    for _ in 0..500 {
        sim.step(DT);
    }
    assert_eq!(swept(sim).0, mine, "standing still sweeps nothing more");
    // Bump and go on the laser: forward; near something, turn for a while.
    let (mut laser, mut turn, mut seed, mut last) = (Laser::default(), 0usize, 7u64, mine);
    for k in 0..30_000 {
        if k % 10 == 0 {
            sim.laser(0, &mut laser);
            if turn == 0 && front(&laser, 35.0) < 500.0 {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                turn = 8 + (seed >> 60) as usize; // 0.8 to 2.3 s
            }
            let m = if turn > 0 {
                turn -= 1;
                Motors { v: 0.0, w: 60.0 }
            } else {
                Motors { v: 400.0, w: 0.0 }
            };
            sim.set_motors(0, m);
        }
        sim.step(DT);
        let (now, all) = swept(sim);
        assert!(now >= last && now <= all, "{now} of {all} after {last}");
        last = now;
    }
    let score = sim.score().unwrap().clone();
    println!("flat, bump and go, 300 s: {}", score.summary());
    assert!(last > 10 * mine, "{}", score.summary());
    assert!(score.summary().ends_with("in 305 s"), "{}", score.summary());
}

/// Pure pursuit along a closed polyline: the point `ahead` mm further along the
/// line than the robot's nearest point.
fn pursue(line: &[Point2], p: Point2, ahead: f64) -> Point2 {
    let n = line.len();
    let (mut best, mut at) = (f64::INFINITY, (0, line[0]));
    for k in 0..n {
        let q = closest_on(p, line[k], line[(k + 1) % n]);
        let d = (q[0] - p[0]).hypot(q[1] - p[1]);
        if d < best {
            (best, at) = (d, (k, q));
        }
    }
    let (mut k, mut q, mut left) = (at.0, at.1, ahead);
    loop {
        let b = line[(k + 1) % n];
        let l = (b[0] - q[0]).hypot(b[1] - q[1]);
        if l >= left {
            return [
                q[0] + (b[0] - q[0]) * left / l,
                q[1] + (b[1] - q[1]) * left / l,
            ];
        }
        (left, q, k) = (left - l, b, (k + 1) % n);
    }
}

/// The motors command that steers robot 0 to `goal` at `v` mm/s (pure pursuit's arc).
fn steer(sim: &Sim, goal: Point2, v: f64) -> Motors {
    let p = sim.robots[0].pose;
    let (dx, dy) = (goal[0] - p.x, goal[1] - p.y);
    let (s, c) = p.theta.sin_cos();
    let (x, y) = (c * dx + s * dy, -s * dx + c * dy);
    let curvature = 2.0 * y / (x * x + y * y).max(1.0);
    Motors {
        v: v as f32,
        w: (v * curvature).to_degrees().clamp(-90.0, 90.0) as f32,
    }
}

#[test]
fn pure_pursuit_on_the_line_completes_a_lap_near_it() {
    let mut s = simulation("line_circuit", "score lap\n").unwrap();
    let sim = &mut s.sim;
    let line = sim.world.paint[0].points.clone();
    let mut steps = 0;
    while !matches!(sim.score(), Some(Score::Lap(l)) if !l.laps.is_empty()) {
        assert!(
            steps < 20_000,
            "no lap in 200 s: {}",
            sim.score().unwrap().summary()
        );
        let p = sim.robots[0].pose;
        let m = steer(sim, pursue(&line, [p.x, p.y], 400.0), 600.0);
        sim.set_motors(0, m);
        sim.step(DT);
        steps += 1;
    }
    let Some(Score::Lap(l)) = sim.score() else {
        unreachable!()
    };
    let lap = &l.laps[0];
    println!(
        "line_circuit, pure pursuit at 600 mm/s: {}",
        sim.score().unwrap().summary()
    );
    // 37 m at 0.6 m/s is 62 s, plus the start's acceleration.
    assert!((55.0..75.0).contains(&lap.time), "{lap:?}");
    assert!(lap.mean < 40.0 && lap.max < 150.0, "{lap:?}");
}

/// A VFF step for robot 0: pulled to `goal`, pushed off what the laser sees
/// within 1.5 m; with something right in front, it turns on the spot to the
/// freer side. Returns the command.
fn vff(sim: &Sim, laser: &Laser, goal: Point2) -> Motors {
    let p = sim.robots[0].pose;
    let (dx, dy) = (goal[0] - p.x, goal[1] - p.y);
    let (s, c) = p.theta.sin_cos();
    let d = dx.hypot(dy).max(1.0);
    let mut f = [(c * dx + s * dy) / d, (-s * dx + c * dy) / d];
    let (mut left, mut right) = (0.0, 0.0);
    for (i, &r) in laser.readings.iter().enumerate() {
        let r = r as f64;
        let deg = laser.start as f64 + i as f64 / laser.resolution as f64;
        *if deg > 0.0 { &mut left } else { &mut right } += r;
        if r < 1500.0 {
            let a = deg.to_radians();
            let push = 0.12 * ((1500.0 - r) / 1500.0).powi(2);
            f[0] -= push * a.cos();
            f[1] -= push * a.sin();
        }
    }
    if front(laser, 60.0) < 450.0 {
        let w = if left > right { 40.0 } else { -40.0 };
        return Motors { v: 0.0, w };
    }
    let angle = f[1].atan2(f[0]);
    Motors {
        v: (500.0 * angle.cos().max(0.0)).max(60.0) as f32,
        w: (2.0 * angle.to_degrees()).clamp(-60.0, 60.0) as f32,
    }
}

#[test]
fn a_vff_robot_reaches_every_target_in_order() {
    let mut s = simulation("obstacle_circuit", "score targets\n").unwrap();
    let sim = &mut s.sim;
    let targets = sim.world.targets.clone();
    let (mut laser, mut next, mut steps) = (Laser::default(), 0, 0);
    let mut m = Motors::default();
    while next < targets.len() {
        assert!(
            steps < 30_000,
            "stuck after 300 s: {}",
            sim.score().unwrap().summary()
        );
        let p = sim.robots[0].pose;
        // The student's own rule: reached within 400 mm (the score counts 500).
        if (targets[next][0] - p.x).hypot(targets[next][1] - p.y) < 400.0 {
            next += 1;
            continue;
        }
        if steps % 10 == 0 {
            sim.laser(0, &mut laser);
            m = vff(sim, &laser, targets[next]);
        }
        sim.set_motors(0, m);
        sim.step(DT);
        steps += 1;
    }
    let Some(Score::Targets(t)) = sim.score() else {
        panic!("no targets score")
    };
    println!("obstacle_circuit, VFF: {}", sim.score().unwrap().summary());
    assert_eq!((t.reached, t.total), (8, 8));
    assert!(t.last.is_some_and(|l| l <= sim.time), "{t:?}");
}

#[test]
fn a_score_the_world_cannot_keep_is_refused_with_its_line() {
    let e = simulation("simple", "robot r 1000 1000 0\nscore targets\n").unwrap_err();
    assert!(
        e.starts_with("<inline>:3:") && e.contains("no targets") && e.contains("target X Y"),
        "{e}"
    );
    let e = simulation("flat", "score lap\n").unwrap_err();
    assert!(e.contains("closed painted line"), "{e}");
    let e = simulation("flat", "score dust\n").unwrap_err();
    assert!(e.contains("<inline>:2") && e.contains("swept"), "{e}");
    let e = simulation("flat", "camera_tilt -60\n").unwrap_err();
    assert!(e.contains("-46"), "{e}");
    // As `jderobot check` sees it: the loads fail on the score's line.
    let text = format!(
        "driver simulator\nworld {}\nscore lap\nend_driver\nload_driver simulator\n",
        world_path("simple.world")
    );
    let conf = Conf::parse(&text, Path::new("test.conf")).unwrap();
    assert!(jderobot::loader::check(&conf).is_empty());
    let e = jderobot::loader::check_loads(&conf)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("test.conf:3:") && e.contains("closed painted line"),
        "{e}"
    );
}

/// The driver exports the score as `world.score`, at the simulation's clock.
#[test]
fn the_driver_exports_the_score_at_its_clock() {
    let rt = start_conf(&format!(
        "driver simulator\nworld {}\nprovides encoders\nprovides motors\nscore swept\nstepped 100\n\
         end_driver\nload_driver simulator\n",
        world_path("flat.world")
    ));
    let live = world::score(&rt.names).expect("world.score");
    let motors = rt.interfaces.get::<Motors>("motors").unwrap();
    assert!(matches!(&**live.load(), Score::Swept(s) if s.time == 0.0));
    // 30 commands of 100 ms each: 3 simulated seconds, whatever the wall clock.
    let time = || match &**live.load() {
        Score::Swept(s) => s.time,
        _ => f64::NAN,
    };
    for k in 1..=30 {
        motors.publish(Motors { v: 300.0, w: 0.0 }).unwrap();
        eventually("100 ms more", || time() >= k as f64 * 0.1 - 0.051);
    }
    std::thread::sleep(std::time::Duration::from_millis(50));
    assert!((time() - 3.0).abs() < 0.051, "{} s", time());
    let summary = live.load().summary();
    assert!(
        summary.starts_with("swept ") && summary.contains("of the floor"),
        "{summary}"
    );
    rt.shutdown();
}
