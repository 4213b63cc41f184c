//! Scans carry their geometry: the same room scanned 90°, 180° and 360° wide (at
//! several resolutions) gives VFF the same forces, the polar view the same points,
//! and Foxglove and the recorder the same angles, whether the scan comes from the
//! simulator, a Gazebo LaserScan or a Player ranger.
#![cfg(all(feature = "simulator", feature = "introrob"))]

use jderobot::{
    drivers::simulator::{RobotModel, Sim},
    interfaces::{Encoders, Laser, LaserMap, Mount},
    schemas::introrob::vff::{self, VffParams},
    widgets::laser_points,
    world::World,
};

/// Scans as (readings, readings per degree): 90°, 180° and 360° wide.
const SCANS: &[(usize, f64)] = &[(90, 1.0), (180, 1.0), (360, 1.0), (45, 0.5), (720, 2.0)];

/// The wall ahead of the robot (robot frame, mm): x = 600, |y| <= 300. Nothing
/// else is in range, so every scan that is at least 90° wide sees all of it.
const WALL_X: f64 = 600.0;
const WALL_HALF: f64 = 300.0;

/// The range (m) from a laser at `o` (robot frame, mm) along `a` rad to the wall,
/// or infinity (no return).
fn wall_range(o: [f64; 2], a: f64) -> f64 {
    let c = a.cos();
    if c <= 1e-9 {
        return f64::INFINITY;
    }
    let t = (WALL_X - o[0]) / c;
    let y = o[1] + t * a.sin();
    if y.abs() <= WALL_HALF {
        t / 1000.0
    } else {
        f64::INFINITY
    }
}

/// The robot at the origin facing +x, in a world with only the wall.
fn simulated(n: usize, res: f64) -> Laser {
    let mut w = World::new();
    w.add_wall(
        [WALL_X, -WALL_HALF],
        [WALL_X, WALL_HALF],
        1000.0,
        [200, 200, 200],
    );
    let mut sim = Sim::new(w, 1);
    let model = RobotModel {
        laser_count: n,
        laser_resolution: res,
        ..RobotModel::default()
    };
    let r = sim.add_robot("r", model, 0.0, 0.0, 0.0);
    let mut l = Laser::default();
    sim.laser(r, &mut l);
    l
}

/// A Gazebo LaserScan of the wall from a 0.5° lidar at the robot's centre, as
/// `gz::msgs::LaserScan` carries it, through the gazebo driver's conversion.
fn gazebo(n: usize, res: f64) -> Laser {
    let (min, step, count) = (-std::f64::consts::PI, 0.5f64.to_radians(), 720);
    let ranges: Vec<u8> = (0..count)
        .flat_map(|k| wall_range([0.0, 0.0], min + k as f64 * step).to_le_bytes())
        .collect();
    let scan = jderobot::drivers::gazebo::pb::Scan {
        angle_min: min,
        angle_step: step,
        range_max: 8.0,
        count,
        ranges: &ranges,
        time: None,
    };
    let mut l = Laser::default();
    jderobot::drivers::gazebo::laser(&mut LaserMap::new(n, res), &scan, &mut l);
    l
}

/// A Player ranger (a 1° 360° Stage laser 19 mm ahead, as the player driver maps
/// it), big-endian doubles as the Player wire carries them.
fn player(n: usize, res: f64) -> Laser {
    use jderobot::drivers::player::{sinks, xdr::RangerConfig};
    let count = 360;
    let cfg = RangerConfig {
        min_angle: -std::f64::consts::PI,
        max_angle: std::f64::consts::PI,
        angular_res: 1f64.to_radians(),
        min_range: 0.0,
        max_range: 8.0,
        range_res: 0.0,
        frequency: 10.0,
    };
    let o = [Mount::PIONEER_LASER.x as f64, 0.0];
    let ranges: Vec<u8> = (0..count)
        .flat_map(|k| wall_range(o, cfg.min_angle + k as f64 * cfg.angular_res).to_be_bytes())
        .collect();
    let mut l = Laser::default();
    let mut map = LaserMap::new(n, res).mounted(Mount::PIONEER_LASER);
    sinks::laser_f64(&mut map, &cfg, count, &ranges, &mut l);
    l
}

/// Two forces agree within a reading's width: the sum over readings of `step`
/// degrees each differs from another resolution's by a few per cent per degree
/// of step, in size and direction.
fn assert_same_force(what: &str, a: [f32; 2], b: [f32; 2], step_deg: f32) {
    let (ma, mb) = (a[0].hypot(a[1]), b[0].hypot(b[1]));
    let tolerance = 0.04 * step_deg.max(1.0);
    assert!(
        (ma - mb).abs() <= tolerance * mb,
        "{what}: |{a:?}| vs |{b:?}|"
    );
    let cos = (a[0] * b[0] + a[1] * b[1]) / (ma * mb);
    let turn = cos.clamp(-1.0, 1.0).acos().to_degrees();
    assert!(turn <= step_deg, "{what}: {a:?} vs {b:?}, {turn}° apart");
}

/// The returns of a scan as points in the robot's frame (mm).
fn wall_points(l: &Laser) -> Vec<[f32; 2]> {
    (0..l.readings.len())
        .filter(|&i| l.is_return(l.readings[i]))
        .map(|i| l.robot_point(i))
        .collect()
}

/// Every source: the scan's width is its own, and the wall is where it is.
fn check_source(name: &str, scan: fn(usize, f64) -> Laser) {
    let pose = Encoders::from_pose(0.0, 0.0, 0.0);
    let p = VffParams::default();
    let target = [5000.0, 0.0];
    let reference = vff::forces(&pose, &scan(180, 1.0), target, &p);
    for &(n, res) in SCANS {
        let l = scan(n, res);
        let what = format!("{name}: {n} readings at {res}/deg");
        assert_eq!(l.readings.len(), n, "{what}");
        // The scan spans its own width, centred ahead.
        let width = (n as f32 - 1.0) / res as f32;
        assert!((l.end() - l.start - width).abs() < 1e-3, "{what}");
        assert!(
            (l.start + l.end()).abs() < 1.0 / res as f32 + 1e-3,
            "{what}"
        );
        // Every return lies on the wall, in the robot's frame.
        let pts = wall_points(&l);
        assert!(
            pts.len() >= (45.0 * res) as usize,
            "{what}: {} returns",
            pts.len()
        );
        // A reading is its nearest ray: at the wall's ends, within a ray's width.
        let edge = WALL_X as f32 * 1f32.to_radians() + 2.0;
        for q in &pts {
            assert!((q[0] - WALL_X as f32).abs() <= edge, "{what}: {q:?}");
            assert!(q[1].abs() <= WALL_HALF as f32 + edge, "{what}: {q:?}");
        }
        // VFF: the same repulsion as from 4.3's 180 readings, within a reading's width.
        let f = vff::forces(&pose, &l, target, &p);
        assert!(
            reference.repulsive[0].hypot(reference.repulsive[1]) > 0.1,
            "{what}: the wall repels"
        );
        assert_same_force(&what, f.repulsive, reference.repulsive, l.step());
        // The polar view: the wall's readings at the same angles and ranges.
        let polar = laser_points(&l);
        for (i, (deg, r)) in polar.iter().enumerate() {
            assert_eq!(*deg, l.robot_angle(i), "{what}");
            assert_eq!(*r, l.readings[i] as f32, "{what}");
        }
        let ahead = l.index_at(0.0).expect("the scan covers straight ahead");
        let mount_x = l.mount.x;
        assert!(
            (polar[ahead].1 + mount_x - WALL_X as f32).abs() <= 1.0,
            "{what}: ahead {:?}",
            polar[ahead]
        );
        check_encoders(&what, &l);
    }
}

/// The recorder's and Foxglove's LaserScan carry the same first and last angle
/// and mounting as the value.
fn check_encoders(what: &str, l: &Laser) {
    use jderobot::mcapfmt::{Recorded, protobuf};
    let (start, end) = ((l.start as f64).to_radians(), (l.end() as f64).to_radians());
    let mut out = Vec::new();
    protobuf::laser_scan("laser", 1, l, &mut out);
    let (_, back) = protobuf::decode_laser("laser", &out, 0).unwrap();
    let Recorded::Laser(back) = back else {
        panic!("{what}: not a laser")
    };
    assert!(
        (back.start - l.start).abs() < 1e-4,
        "{what}: recorder start"
    );
    assert!((back.end() - l.end()).abs() < 1e-3, "{what}: recorder end");
    assert_eq!(back.mount, l.mount, "{what}: recorder mount");
    #[cfg(feature = "foxglove")]
    {
        let f = jderobot::services::foxglove::channels::laser_scan(std::time::UNIX_EPOCH, l);
        assert!(
            (f.start_angle - start).abs() < 1e-6,
            "{what}: foxglove start"
        );
        if l.readings.len() > 1 {
            assert!((f.end_angle - end).abs() < 1e-6, "{what}: foxglove end");
        }
        let pos = f.pose.and_then(|p| p.position).expect("a pose");
        assert!((pos.x * 1000.0 - l.mount.x as f64).abs() < 1e-6, "{what}");
    }
    #[cfg(not(feature = "foxglove"))]
    let _ = (start, end);
}

#[test]
fn the_simulator_scans_any_width_with_its_geometry() {
    check_source("simulator", simulated);
    // The simulator's laser is a Pioneer's, 19 mm ahead: written once.
    assert_eq!(simulated(180, 1.0).mount, Mount::PIONEER_LASER);
}

#[test]
fn gazebo_scans_any_width_with_its_geometry() {
    check_source("gazebo", gazebo);
}

#[test]
fn player_scans_any_width_with_its_geometry() {
    check_source("player", player);
}

#[test]
fn the_three_sources_agree() {
    let pose = Encoders::from_pose(0.0, 0.0, 0.0);
    let p = VffParams::default();
    for &(n, res) in SCANS {
        let f: Vec<[f32; 2]> = [simulated, gazebo, player]
            .iter()
            .map(|s| vff::forces(&pose, &s(n, res), [5000.0, 0.0], &p).repulsive)
            .collect();
        for g in &f[1..] {
            assert_same_force(&format!("{n} at {res}"), *g, f[0], 1.0 / res as f32);
        }
    }
}
