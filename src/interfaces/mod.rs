//! Interfaces: the seed's named, typed sensor and actuator variables ("virtual
//! schemas" in 4.3).
//!
//! | name | type | fields and units |
//! |---|---|---|
//! | `colorA..D` | [`Image`] | 320x240, BGR bytes, rows top to bottom |
//! | `varcolorA..D` | [`Image`] | any size, BGR |
//! | `laser` | [`Laser`] | `readings` mm (index 0 = right, centre = ahead), `resolution` readings/deg |
//! | `sonars` | [`Sonars`] | `us` mm, one per sonar |
//! | `encoders` | [`Encoders`] | `x`, `y` mm, `theta` rad in (0, 2π], `cos`, `sin` (the seed's `robot[5]`) |
//! | `motors` | [`Motors`] | `v` mm/s, `w` deg/s (counter-clockwise positive) |
//! | `pantiltencoders` | [`PtEncoders`] | `pan_angle`, `tilt_angle` deg |
//! | `pantiltmotors` | [`PtMotors`] | `longitude`, `latitude` deg; speeds deg/s; limits |
//! | `zoomencoders` | [`ZoomEncoders`] | `zoom_position` |
//! | `zoommotors` | [`ZoomMotors`] | `zoom`, `zoom_speed`; limits |
//! | `bumpers` | [`Bumpers`] | one byte per bumper, 1 = pressed |
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
//! no reader still holds it, so a steady stream of frames allocates nothing.
//!
//! Resume/suspend reference counting ([`Interface::resume`]) tells a driver whether
//! anybody uses an interface, so it works only while someone does.
mod cell;
mod names;
mod table;
mod values;

pub use cell::{AnyInterface, Interface, Notify, Sample, Watch};
pub use names::{STANDARD_NAMES, canonical, family, interface_name};
pub use table::{InUse, InterfaceError, Interfaces};
pub use values::{
    Bumpers, COLOR_HEIGHT, COLOR_WIDTH, Encoders, Image, InterfaceValue, Laser, Motors, PtEncoders,
    PtMotors, Sonars, ZoomEncoders, ZoomMotors, limit,
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
}
