//! Interfaces: the seed's named, typed sensor and actuator variables ("virtual
//! schemas" in 4.3).
//!
//! | name | type | fields and units |
//! |---|---|---|
//! | `colorA..D` | [`Image`] | 320x240, BGR bytes, rows top to bottom |
//! | `varcolorA..D` | [`Image`] | any size, BGR |
//! | `laser` | [`Laser`] | `readings` mm (index 0 = right, centre = ahead), `resolution` readings/deg |
//! | `sonars` | [`Sonars`] | `us` mm, one per sonar |
//! | `encoders` | [`Encoders`] | `x`, `y` mm, `theta` rad in (0, 2π], `cos`, `sin` (the seed's `robot[5]`); printed (`echo`, the panels) as a [`heading`] in (−180°, 180°] |
//! | `motors` | [`Motors`] | `v` mm/s, `w` deg/s (counter-clockwise positive); \|v\| <= [`MAX_MOTOR_V`], \|w\| <= [`MAX_MOTOR_W`] |
//! | `pantiltencoders` | [`PtEncoders`] | `pan_angle`, `tilt_angle` deg |
//! | `pantiltmotors` | [`PtMotors`] | `longitude`, `latitude` deg; speeds deg/s; limits |
//! | `zoomencoders` | [`ZoomEncoders`] | `zoom_position` |
//! | `zoommotors` | [`ZoomMotors`] | `zoom`, `zoom_speed`; limits |
//! | `bumpers` | [`Bumpers`] | one byte per bumper, 1 = pressed |
//! | `imu` | [`Imu`] | orientation `qx qy qz qw` (unit quaternion), angular velocity `wx wy wz` rad/s, linear acceleration `ax ay az` m/s² |
//!
//! The kinds and their value types are listed once, in the table of `kinds.rs`; a
//! kind is a [`Kind`] (an enum, never a string), and code that handles any kind
//! dispatches through the table ([`with_kind!`]).
//!
//! 4.3's export names `ptencoders`, `ptmotors`, `zencoders`, `zmotors` are accepted
//! as aliases. A driver serving several robots names them with a suffix
//! (`laser robot2` provides `laser.robot2`, see [`interface_name`]).
//!
//! Every interface holds its latest [`Sample`]: a clock that increases with every
//! new value, a timestamp and the value. A read ([`Interface::read`]) is an atomic
//! pointer load: no copy of an image, no lock held while the reader works on it. A
//! write ([`Interface::publish`], [`Interface::write`]) swaps in a new sample and
//! never waits for readers; [`Interface::write`] recycles the previous buffer when
//! no reader still holds it (or once the reader that held it lets go), so a steady
//! stream of frames allocates and copies nothing.
//!
//! Every write is checked by the value type's one validation
//! ([`InterfaceValue::validate`], ranges in [`RANGES`]): numbers finite and within
//! their documented range, so a NaN, an inf or a 1e38 never reaches a schema. A
//! driver or transport writes what comes from outside with
//! [`Interface::accept`] or [`Interface::receive`] (with the sender's clock),
//! naming a [`Source`]: a refused value is logged once per change of state of
//! that source. The clock only grows: a sender's clock is taken only when it is
//! ahead of the local one and at most [`MAX_CLOCK`].
//!
//! Resume/suspend reference counting ([`Interface::resume`]) tells a driver whether
//! anybody uses an interface, so it works only while someone does.
mod cell;
mod kinds;
mod laser_map;
mod names;
mod source;
mod table;
mod values;

pub use cell::{AnyInterface, HISTORY, Interface, MAX_CLOCK, Notify, Sample, Watch};
pub use kinds::Kind;
#[allow(unused_imports)] // with_kind: only components behind cargo features use it
pub(crate) use kinds::{for_each_kind, with_kind, with_kind_match};
pub use laser_map::LaserMap;
pub use names::{IMAGE_NAMES, STANDARD_NAMES, canonical, family, interface_name};
pub use source::Source;
pub use table::{InUse, InterfaceError, Interfaces};
pub use values::{
    Bumpers, COLOR_HEIGHT, COLOR_WIDTH, Encoders, Image, Imu, InterfaceValue,
    JDE43_LASER_MAX_RANGE, JDE43_LASER_START, Laser, MAX_ACCELERATION, MAX_ANGLE_DEG,
    MAX_ANGULAR_VELOCITY, MAX_MOTOR_V, MAX_MOTOR_W, MAX_POSITION_MM, MAX_PT_SPEED, MAX_RANGE_MM,
    Motors, Mount, PtEncoders, PtMotors, RANGES, Sonars, ZoomEncoders, ZoomMotors, heading, limit,
};

#[cfg(test)]
mod tests {
    use super::*;
    use std::{sync::Arc, time::Duration};

    #[test]
    fn a_watch_wakes_its_thread_on_publish_until_unwatched() {
        let i: Arc<Interface<Motors>> = Arc::new(Interface::new("motors", "test"));
        let w = Watch::for_current_thread();
        i.watch(w.clone());
        assert!(!w.wait(Duration::from_millis(10)), "nothing published yet");
        let writer = {
            let i = i.clone();
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(20));
                i.publish(Motors { v: 1.0, w: 0.0 }).unwrap();
            })
        };
        assert!(w.wait(Duration::from_secs(10)), "woken by the publish");
        writer.join().unwrap();
        i.unwatch(&*w);
        i.publish(Motors { v: 2.0, w: 0.0 }).unwrap();
        assert!(!w.wait(Duration::from_millis(10)), "unwatched");
    }

    #[test]
    fn clock_increases_and_read_sees_latest() {
        let i: Interface<Motors> = Interface::new("motors", "test");
        assert_eq!(i.read().clock, 0);
        i.publish(Motors { v: 1.0, w: 2.0 }).unwrap();
        i.write(|m| m.v = 5.0).unwrap();
        let s = i.read();
        assert_eq!(s.clock, 2);
        assert_eq!(s.v, 5.0);
        assert_eq!(s.w, 2.0);
    }

    #[test]
    fn color_must_be_320x240() {
        let t = Interfaces::default();
        let c = t
            .provide_value("colorA", "t", Image::new(320, 240))
            .unwrap();
        assert!(
            c.publish(Image::new(640, 480))
                .unwrap_err()
                .to_string()
                .contains("320x240")
        );
        let v = t.provide::<Image>("varcolorA", "t").unwrap();
        v.publish(Image::new(640, 480)).unwrap();
    }

    #[test]
    fn typed_lookup_and_aliases() {
        let t = Interfaces::default();
        t.provide::<PtMotors>("pantiltmotors", "t").unwrap();
        assert!(t.get::<PtMotors>("ptmotors").is_ok());
        assert!(matches!(
            t.get::<Laser>("ptmotors"),
            Err(InterfaceError::WrongType { .. })
        ));
        assert!(matches!(
            t.get::<Laser>("laser"),
            Err(InterfaceError::Missing { .. })
        ));
        assert!(matches!(
            t.provide::<PtMotors>("ptmotors", "u"),
            Err(InterfaceError::Duplicate { .. })
        ));
    }

    #[test]
    fn stale_motor_command_is_zero() {
        let m: Interface<Motors> = Interface::new("motors", "t");
        m.publish(Motors { v: 300.0, w: 0.0 }).unwrap();
        assert_eq!(m.command(Duration::from_secs(10)).v, 300.0);
        std::thread::sleep(Duration::from_millis(20));
        assert_eq!(m.command(Duration::from_millis(5)), Motors::default());
    }

    #[test]
    fn stale_until_next_publish() {
        let l: Interface<Laser> = Interface::new("laser", "t");
        assert_eq!(l.stale(), None);
        l.set_stale("player: localhost:6665 closed the connection");
        assert!(AnyInterface::stale(&l).unwrap().contains("6665"));
        l.publish(Laser::default()).unwrap();
        assert_eq!(l.stale(), None);
    }

    #[test]
    fn fingerprints_tell_new_values_from_repeats() {
        let a = Image::new(64, 48);
        let mut b = a.clone();
        assert_eq!(a.fingerprint(), b.fingerprint());
        b.data[1000] = 1;
        assert_ne!(a.fingerprint(), b.fingerprint());
        assert_ne!(Image::new(48, 64).fingerprint(), a.fingerprint());
        let m = Motors { v: 1.0, w: 0.0 };
        assert_eq!(m.fingerprint(), m.fingerprint());
        assert_ne!(m.fingerprint(), Motors::default().fingerprint());
    }

    #[test]
    fn non_finite_and_out_of_range_values_are_refused_by_every_write() {
        let m: Interface<Motors> = Interface::new("motors", "t");
        for bad in [
            Motors {
                v: f32::NAN,
                w: 0.0,
            },
            Motors {
                v: 0.0,
                w: f32::INFINITY,
            },
        ] {
            let e = m.publish(bad).unwrap_err().to_string();
            assert!(e.contains("not a finite number"), "{e}");
        }
        assert!(m.write(|v| v.v = f32::NEG_INFINITY).is_err());
        assert!(
            m.publish_recorded(
                5,
                std::time::SystemTime::now(),
                Motors {
                    v: f32::NAN,
                    w: 0.0
                }
            )
            .is_err()
        );
        assert_eq!(m.clock(), 0, "nothing published");
        let e: Interface<Encoders> = Interface::new("encoders", "t");
        assert!(e.publish(Encoders::from_pose(f32::NAN, 0.0, 0.0)).is_err());
        let huge = e
            .publish(Encoders::from_pose(1e38, 0.0, 0.0))
            .unwrap_err()
            .to_string();
        assert!(huge.contains("out of its range"), "{huge}");
        e.publish(Encoders::from_pose(12_000.0, -3_000.0, 7.0))
            .unwrap();
        let pt: Interface<PtEncoders> = Interface::new("pantiltencoders", "t");
        assert!(
            pt.publish(PtEncoders {
                pan_angle: 158_929.0,
                tilt_angle: 0.0
            })
            .is_err()
        );
        let ptm: Interface<PtMotors> = Interface::new("pantiltmotors", "t");
        assert!(ptm.set_fields(&[("longitude", "NaN")]).is_err());
        let v = PtMotors {
            latitude_speed: f32::NAN,
            ..Default::default()
        };
        assert!(ptm.publish(v).is_err());
        let l: Interface<Laser> = Interface::new("laser", "t");
        assert!(
            l.publish(Laser {
                readings: vec![100, -5],
                resolution: 1.0,
                ..Laser::default()
            })
            .is_err()
        );
        let s: Interface<Sonars> = Interface::new("sonars", "t");
        assert!(s.publish(Sonars { us: vec![f32::NAN] }).is_err());
        let z: Interface<ZoomEncoders> = Interface::new("zoomencoders", "t");
        assert!(
            z.publish(ZoomEncoders {
                zoom_position: f32::INFINITY
            })
            .is_err()
        );
    }

    #[test]
    fn a_received_clock_never_wraps_or_regresses_the_interface_clock() {
        let now = std::time::SystemTime::now;
        let from = Source::new("test");
        let m: Interface<Motors> = Interface::new("motors", "t");
        assert_eq!(m.receive(&from, 10, now(), |v| v.v = 1.0), Some(10));
        // Behind: the next local clock.
        assert_eq!(m.receive(&from, 3, now(), |v| v.v = 2.0), Some(11));
        // Absurd: refused as a recorded clock, ignored as a received one.
        assert!(m.write_recorded(u64::MAX, now(), |v| v.v = 3.0).is_err());
        assert!(
            m.publish_recorded(MAX_CLOCK + 1, now(), Motors::default())
                .is_err()
        );
        assert_eq!(m.receive(&from, u64::MAX, now(), |v| v.v = 4.0), Some(12));
        assert_eq!(m.publish(Motors::default()).unwrap(), 13);
        assert_eq!(m.clock(), 13);
        // An invalid value is refused and the clock stays.
        assert_eq!(m.receive(&from, 20, now(), |v| v.v = f32::NAN), None);
        assert_eq!(m.clock(), 13);
        assert!(from.refusing());
        assert_eq!(m.receive(&from, 20, now(), |v| v.v = 5.0), Some(20));
        assert!(!from.refusing());
    }

    #[test]
    fn a_source_logs_once_per_change_of_state() {
        let from = Source::new("test").with_quiet(Duration::ZERO);
        assert!(from.refused("bad"), "the first refusal is logged");
        assert!(!from.refused("bad"), "the second is not");
        from.accepted();
        assert!(from.refused("bad"), "after a good value, logged again");
        // A flapping source: once per quiet time.
        let flapping = Source::new("test");
        assert!(flapping.refused("bad"));
        for _ in 0..10 {
            flapping.accepted();
            assert!(!flapping.refused("bad"), "within the quiet time");
        }
        let m: Interface<Motors> = Interface::new("motors", "t");
        assert_eq!(m.accept(&from, Motors { v: 1.0, w: 0.0 }), Some(1));
        assert!(!from.refusing());
        assert_eq!(m.accept_with(&from, |v| v.w = f32::NAN), None);
        assert!(from.refusing());
    }
}
