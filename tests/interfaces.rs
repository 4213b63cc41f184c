//! Interfaces under concurrent readers and writers, reference counting, the name
//! space and motor safety.

use std::{
    sync::{
        Arc, Barrier,
        atomic::{AtomicBool, Ordering},
    },
    thread,
    time::Duration,
};

use jderobot::{
    interfaces::{Encoders, Image, Interface, InterfaceError, Interfaces, Motors, PtMotors},
    namespace::{Namespace, NamespaceError},
};

/// Every frame is filled with one byte derived from its clock, so a reader can see
/// a torn frame (bytes from two frames) or a clock that goes backwards.
#[test]
fn readers_never_see_torn_images_or_clocks_going_back() {
    let iface: Arc<Interface<Image>> = Arc::new(Interface::with_value(
        "varcolorA",
        "test",
        Image::new(640, 480),
    ));
    let done = Arc::new(AtomicBool::new(false));
    let start = Arc::new(Barrier::new(9));
    let readers: Vec<_> = (0..8)
        .map(|_| {
            let (iface, done, start) = (iface.clone(), done.clone(), start.clone());
            thread::spawn(move || {
                start.wait();
                let mut last = 0;
                let mut reads = 0u64;
                while !done.load(Ordering::Acquire) {
                    let s = iface.read();
                    assert!(s.clock >= last, "clock went back: {} < {last}", s.clock);
                    last = s.clock;
                    let want = (s.clock % 251) as u8;
                    // Check a spread of bytes, first and last included.
                    let d = &s.value.data;
                    for i in (0..d.len()).step_by(4099).chain([d.len() - 1]) {
                        assert_eq!(d[i], want, "torn frame at clock {}", s.clock);
                    }
                    reads += 1;
                }
                reads
            })
        })
        .collect();
    start.wait();
    for _ in 0..2000 {
        iface
            .write(|img| {
                let c = ((iface.clock() + 1) % 251) as u8;
                img.data.fill(c);
            })
            .unwrap();
    }
    done.store(true, Ordering::Release);
    let reads: u64 = readers.into_iter().map(|r| r.join().unwrap()).sum();
    assert_eq!(iface.clock(), 2000);
    assert!(reads > 0);
}

#[test]
fn concurrent_writers_keep_clock_unique_and_increasing() {
    let iface: Arc<Interface<Motors>> = Arc::new(Interface::new("motors", "test"));
    let writers: Vec<_> = (0..4)
        .map(|k| {
            let iface = iface.clone();
            thread::spawn(move || {
                let mut clocks = Vec::new();
                for i in 0..500 {
                    clocks.push(
                        iface
                            .publish(Motors {
                                v: (k * 1000 + i) as f32,
                                w: 0.0,
                            })
                            .unwrap(),
                    );
                }
                clocks
            })
        })
        .collect();
    let mut all: Vec<u64> = writers
        .into_iter()
        .flat_map(|w| w.join().unwrap())
        .collect();
    all.sort_unstable();
    all.dedup();
    assert_eq!(all.len(), 2000, "every publish gets its own clock");
    assert_eq!(iface.clock(), 2000);
    assert_eq!(iface.read().clock, 2000);
}

#[test]
fn write_recycles_the_buffer_no_reader_holds() {
    let iface: Interface<Image> = Interface::with_value("varcolorB", "t", Image::new(64, 48));
    iface.write(|i| i.data[0] = 1).unwrap();
    iface.write(|i| i.data[0] = 2).unwrap();
    let p1 = iface.read().value.data.as_ptr();
    iface.write(|i| i.data[0] = 3).unwrap();
    iface.write(|i| i.data[0] = 4).unwrap();
    let p2 = iface.read().value.data.as_ptr();
    // Two buffers alternate once no reader holds the old sample.
    assert_eq!(p1, p2);
    // A held snapshot is never overwritten.
    let held = iface.snapshot();
    iface.write(|i| i.data[0] = 5).unwrap();
    iface.write(|i| i.data[0] = 6).unwrap();
    assert_eq!(held.value.data[0], 4);
    assert_eq!(iface.read().value.data[0], 6);
}

/// A reader (a network writer sending a frame) holds the latest sample while the
/// next one is written, then lets it go: the write after that gets the held
/// buffer back (its stale pixels) instead of a copy of the latest frame.
#[test]
fn write_takes_back_a_buffer_its_reader_let_go() {
    let iface: Interface<Image> = Interface::with_value("varcolorB", "t", Image::new(64, 48));
    iface.write(|i| i.data.fill(1)).unwrap();
    let sending = iface.snapshot();
    iface.write(|i| i.data.fill(2)).unwrap();
    drop(sending);
    let mut got = 0;
    iface
        .write(|i| {
            got = i.data[0];
            i.data.fill(3)
        })
        .unwrap();
    assert_eq!(got, 1, "the buffer of frame 1, not a copy of frame 2");
    // One still held is neither taken nor overwritten.
    let kept = iface.snapshot();
    iface.write(|i| i.data.fill(4)).unwrap();
    iface.write(|i| i.data.fill(5)).unwrap();
    assert_eq!(kept.value.data[0], 3);
    assert_eq!(iface.read().value.data[0], 5);
}

/// Two readers holding two frames (a Zenoh publisher: one on the wire, one
/// waiting for room) while the writer goes on: once the older is let go, the
/// next write gets its buffer back, not a copy of the latest frame.
#[test]
fn write_takes_back_a_buffer_when_two_readers_held_frames() {
    let iface: Interface<Image> = Interface::with_value("varcolorB", "t", Image::new(64, 48));
    iface.write(|i| i.data.fill(1)).unwrap();
    let on_the_wire = iface.snapshot();
    iface.write(|i| i.data.fill(2)).unwrap();
    let waiting = iface.snapshot();
    iface.write(|i| i.data.fill(3)).unwrap();
    drop(on_the_wire);
    let mut got = 0;
    iface
        .write(|i| {
            got = i.data[0];
            i.data.fill(5)
        })
        .unwrap();
    assert_eq!(
        got, 1,
        "the buffer of frame 1, let go, not a copy of frame 3"
    );
    assert_eq!(
        waiting.value.data[0], 2,
        "a frame still held is not touched"
    );
    assert_eq!(iface.read().value.data[0], 5);
}

#[test]
fn resume_suspend_reference_counting() {
    let iface: Arc<Interface<Encoders>> = Arc::new(Interface::new("encoders", "t"));
    let handles: Vec<_> = (0..8)
        .map(|_| {
            let iface = iface.clone();
            thread::spawn(move || {
                for _ in 0..1000 {
                    iface.resume();
                    iface.suspend();
                }
                iface.resume();
            })
        })
        .collect();
    for h in handles {
        h.join().unwrap();
    }
    assert_eq!(iface.users(), 8);
    for _ in 0..10 {
        iface.suspend();
    }
    assert_eq!(iface.users(), 0, "never below zero");
    // A driver sleeping in wait_used wakes when someone resumes.
    let waiter = {
        let iface = iface.clone();
        thread::spawn(move || iface.wait_used(Duration::from_secs(10)))
    };
    thread::sleep(Duration::from_millis(20));
    iface.resume();
    assert!(waiter.join().unwrap());
}

#[test]
fn motor_safety_zeroes_stale_commands() {
    let m: Interface<Motors> = Interface::new("motors", "t");
    assert_eq!(
        m.command(Duration::from_secs(1)),
        Motors::default(),
        "never commanded"
    );
    m.publish(Motors { v: 200.0, w: 10.0 }).unwrap();
    assert_eq!(
        m.command(Duration::from_secs(60)),
        Motors { v: 200.0, w: 10.0 }
    );
    thread::sleep(Duration::from_millis(30));
    assert_eq!(m.command(Duration::from_millis(10)), Motors::default());
}

#[test]
fn table_lookup_errors_are_clear() {
    let t = Interfaces::default();
    t.provide::<Motors>("motors", "simulator").unwrap();
    let e = t.get::<PtMotors>("motors").err().unwrap().to_string();
    assert_eq!(
        e,
        "interface `motors` is a motors interface, not pantiltmotors"
    );
    let e = t.get::<Motors>("laser").err().unwrap();
    assert_eq!(
        e,
        InterfaceError::Missing {
            name: "laser".into(),
            available: "motors".into()
        }
    );
    let e = t
        .provide::<Motors>("motors", "player")
        .err()
        .unwrap()
        .to_string();
    assert_eq!(e, "interface `motors` is already provided by simulator");
}

#[test]
fn actuators_are_set_by_field_and_sensors_refuse() {
    let t = Interfaces::default();
    t.provide::<Motors>("motors", "t").unwrap();
    t.provide::<Encoders>("encoders", "t").unwrap();
    let m = t.get_any("motors").unwrap();
    m.set_fields(&[("v", "200"), ("w", "-10.5")]).unwrap();
    assert_eq!(m.describe(), "v=200.0 mm/s w=-10.50 deg/s");
    assert!(
        m.set_fields(&[("speed", "1")])
            .unwrap_err()
            .to_string()
            .contains("no field `speed`")
    );
    assert!(
        m.set_fields(&[("v", "fast")])
            .unwrap_err()
            .to_string()
            .contains("expected a number")
    );
    let e = t.get_any("encoders").unwrap();
    assert!(
        e.set_fields(&[("x", "1")])
            .unwrap_err()
            .to_string()
            .contains("sensor")
    );
}

#[test]
fn namespace_typed_exports() {
    let ns = Namespace::default();
    ns.export("introrob", "v", 1.5f32).unwrap();
    assert_eq!(*ns.import::<f32>("introrob", "v").unwrap(), 1.5);
    assert!(matches!(
        ns.import::<u8>("introrob", "v"),
        Err(NamespaceError::WrongType { .. })
    ));
    assert!(matches!(
        ns.import::<f32>("nobody", "v"),
        Err(NamespaceError::Missing { .. })
    ));
    assert!(matches!(
        ns.export("introrob", "v", 2.0f32),
        Err(NamespaceError::Duplicate { .. })
    ));
    ns.remove_component("introrob");
    assert!(ns.import::<f32>("introrob", "v").is_err());
}

/// A reader that must see every sample (the recorder) gets, after a late wake-up,
/// each one it slept through from the history, oldest first; past the history's
/// length it is told how many are gone; without a history only the latest is there.
#[test]
fn since_gives_every_sample_a_late_reader_slept_through() {
    use jderobot::interfaces::HISTORY;
    let enc = Interface::<Encoders>::new("encoders", "robot");
    let x = |x: f32| Encoders {
        x,
        ..Encoders::default()
    };
    enc.publish(x(1.0)).unwrap();
    let mut out = Vec::new();
    // No history asked for: only the latest.
    enc.publish(x(2.0)).unwrap();
    assert_eq!(enc.since(0, &mut out), 1);
    assert_eq!(out.iter().map(|s| s.clock).collect::<Vec<_>>(), [2]);

    enc.keep_history(true);
    for k in 3..=7 {
        enc.publish(x(k as f32)).unwrap();
    }
    out.clear();
    assert_eq!(enc.since(2, &mut out), 0, "nothing gone");
    assert_eq!(
        out.iter().map(|s| (s.clock, s.value.x)).collect::<Vec<_>>(),
        [(3, 3.0), (4, 4.0), (5, 5.0), (6, 6.0), (7, 7.0)]
    );
    out.clear();
    assert_eq!(enc.since(7, &mut out), 0);
    assert!(out.is_empty(), "nothing new");

    // More than the history holds: the oldest are gone, and counted.
    for k in 0..(HISTORY as u64 + 4) {
        enc.publish(x(k as f32)).unwrap();
    }
    out.clear();
    assert_eq!(enc.since(7, &mut out), 4);
    assert_eq!(out.len(), HISTORY);
    assert_eq!(out[0].clock, 12);
    assert!(out.windows(2).all(|w| w[1].clock == w[0].clock + 1));

    enc.keep_history(false);
    enc.publish(x(0.5)).unwrap();
    out.clear();
    enc.since(enc.clock() - 1, &mut out);
    assert_eq!(out.len(), 1, "history off: the latest alone");
}
