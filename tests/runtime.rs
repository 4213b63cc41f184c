//! The schema runtime through its public API: states, hierarchy, arbitration,
//! panic isolation, cronos. Waits are bounded polls on state, never timing asserts.

use crate::common;

use common::{eventually, state};
use std::{
    path::Path,
    sync::{
        Arc,
        atomic::{AtomicBool, AtomicU64, Ordering},
    },
    time::Duration,
};

use jderobot::{
    Context, Runtime, Schema, State,
    interfaces::{Laser, Motors},
    runtime::{Father, RuntimeError},
};

/// A schema that counts its iterations; its preconditions follow a shared flag.
struct Counter {
    count: Arc<AtomicU64>,
    ready: Arc<AtomicBool>,
    cycle_ms: u64,
}

impl Schema for Counter {
    fn cycle(&self) -> Duration {
        Duration::from_millis(self.cycle_ms)
    }
    fn preconditions(&mut self, _: &Context) -> bool {
        self.ready.load(Ordering::Acquire)
    }
    fn iteration(&mut self, _: &Context) -> anyhow::Result<()> {
        self.count.fetch_add(1, Ordering::AcqRel);
        Ok(())
    }
}

fn counter(rt: &Runtime, name: &str) -> (Arc<AtomicU64>, Arc<AtomicBool>) {
    let count = Arc::new(AtomicU64::new(0));
    let ready = Arc::new(AtomicBool::new(true));
    rt.add_schema(
        name,
        "test counter",
        Box::new(Counter {
            count: count.clone(),
            ready: ready.clone(),
            cycle_ms: 2,
        }),
    )
    .expect("add schema");
    (count, ready)
}

fn runtime() -> Arc<Runtime> {
    Runtime::new(Path::new("test.conf"))
}

#[test]
fn run_iterates_and_stop_sleeps() {
    let rt = runtime();
    let (count, _) = counter(&rt, "a");
    assert_eq!(state(&rt, "a"), State::Slept);
    rt.run("a").unwrap();
    eventually("iterations", || count.load(Ordering::Acquire) >= 5);
    assert_eq!(state(&rt, "a"), State::Winner);
    assert_eq!(rt.run("a"), Err(RuntimeError::AlreadyRunning("a".into())));
    rt.stop("a").unwrap();
    assert_eq!(state(&rt, "a"), State::Slept);
    std::thread::sleep(Duration::from_millis(20));
    let n = count.load(Ordering::Acquire);
    std::thread::sleep(Duration::from_millis(30));
    assert_eq!(
        count.load(Ordering::Acquire),
        n,
        "a stopped schema must not iterate"
    );
    assert_eq!(rt.stop("a"), Err(RuntimeError::NotRunning("a".into())));
    rt.shutdown();
}

#[test]
fn preconditions_give_notready() {
    let rt = runtime();
    let (count, ready) = counter(&rt, "a");
    ready.store(false, Ordering::Release);
    rt.run("a").unwrap();
    eventually("notready", || state(&rt, "a") == State::NotReady);
    assert_eq!(count.load(Ordering::Acquire), 0);
    ready.store(true, Ordering::Release);
    eventually("winner", || state(&rt, "a") == State::Winner);
    eventually("iterates", || count.load(Ordering::Acquire) > 0);
    rt.shutdown();
}

#[test]
fn forced_iterates_whatever_its_preconditions() {
    let rt = runtime();
    let (count, ready) = counter(&rt, "a");
    ready.store(false, Ordering::Release);
    rt.force("a").unwrap();
    eventually("forced iterations", || count.load(Ordering::Acquire) >= 3);
    assert_eq!(state(&rt, "a"), State::Forced);
    rt.shutdown();
}

/// A parent that runs two children with an arbitration following a shared flag.
struct Parent {
    prefer_second: Arc<AtomicBool>,
    children: [&'static str; 2],
}

impl Schema for Parent {
    fn cycle(&self) -> Duration {
        Duration::from_millis(5)
    }
    fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
        let prefer = self.prefer_second.clone();
        let names = self.children;
        ctx.run_children(
            &self.children,
            Some(Arc::new(move |ready: &[&str]| {
                let want = if prefer.load(Ordering::Acquire) {
                    names[1]
                } else {
                    names[0]
                };
                ready.iter().position(|n| *n == want).unwrap_or(0)
            })),
        )?;
        Ok(())
    }
    fn iteration(&mut self, _: &Context) -> anyhow::Result<()> {
        Ok(())
    }
}

#[test]
fn parent_runs_children_and_only_the_winner_iterates() {
    let rt = runtime();
    let (c1, _) = counter(&rt, "left");
    let (c2, ready2) = counter(&rt, "right");
    let prefer_second = Arc::new(AtomicBool::new(false));
    rt.add_schema(
        "parent",
        "test parent",
        Box::new(Parent {
            prefer_second: prefer_second.clone(),
            children: ["left", "right"],
        }),
    )
    .expect("add schema");
    rt.run("parent").unwrap();
    eventually("left wins", || {
        state(&rt, "left") == State::Winner && state(&rt, "right") == State::Ready
    });
    let parent = rt.schema_status("parent").unwrap();
    assert_eq!(parent.children, ["left", "right"]);
    assert_eq!(
        rt.schema_status("left").unwrap().father,
        Father::Schema("parent".into())
    );
    let before = c2.load(Ordering::Acquire);
    eventually("left iterates", || c1.load(Ordering::Acquire) >= 5);
    assert_eq!(
        c2.load(Ordering::Acquire),
        before,
        "the loser must not iterate"
    );

    // The arbitration changes its mind.
    prefer_second.store(true, Ordering::Release);
    eventually("right wins", || {
        state(&rt, "right") == State::Winner && state(&rt, "left") == State::Ready
    });
    eventually("right iterates", || c2.load(Ordering::Acquire) >= 5);

    // A brother whose preconditions fail leaves the field to the other.
    ready2.store(false, Ordering::Release);
    eventually("left wins again", || {
        state(&rt, "left") == State::Winner && state(&rt, "right") == State::NotReady
    });

    // Stopping the parent stops its children.
    rt.stop("parent").unwrap();
    assert_eq!(state(&rt, "left"), State::Slept);
    assert_eq!(state(&rt, "right"), State::Slept);
    rt.shutdown();
}

#[test]
fn without_arbitration_function_first_ready_brother_wins() {
    struct P;
    impl Schema for P {
        fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
            ctx.run_children(&["x", "y"], None)?;
            Ok(())
        }
        fn iteration(&mut self, _: &Context) -> anyhow::Result<()> {
            Ok(())
        }
    }
    let rt = runtime();
    counter(&rt, "x");
    counter(&rt, "y");
    rt.add_schema("p", "", Box::new(P)).expect("add schema");
    let again = rt.add_schema("x", "", Box::new(P)).unwrap_err();
    assert_eq!(again.to_string(), "`x` is already loaded");
    rt.run("p").unwrap();
    eventually("x winner, y ready", || {
        state(&rt, "x") == State::Winner && state(&rt, "y") == State::Ready
    });
    rt.shutdown();
}

struct Panicker {
    after: u64,
    n: u64,
}

impl Schema for Panicker {
    fn cycle(&self) -> Duration {
        Duration::from_millis(1)
    }
    fn iteration(&mut self, _: &Context) -> anyhow::Result<()> {
        self.n += 1;
        if self.n.is_multiple_of(self.after) {
            panic!("boom at iteration {}", self.n);
        }
        Ok(())
    }
}

struct Failer;

impl Schema for Failer {
    fn cycle(&self) -> Duration {
        Duration::from_millis(1)
    }
    fn iteration(&mut self, _: &Context) -> anyhow::Result<()> {
        anyhow::bail!("sensor unplugged")
    }
}

#[test]
fn a_panicking_or_failing_schema_is_stopped_and_the_others_run_on() {
    let rt = runtime();
    let (count, _) = counter(&rt, "healthy");
    rt.add_schema("bad", "", Box::new(Panicker { after: 3, n: 0 }))
        .expect("add schema");
    rt.add_schema("failing", "", Box::new(Failer))
        .expect("add schema");
    rt.run("healthy").unwrap();
    rt.run("bad").unwrap();
    rt.run("failing").unwrap();
    eventually("bad stopped", || state(&rt, "bad") == State::Slept);
    eventually("failing stopped", || state(&rt, "failing") == State::Slept);
    let bad = rt.schema_status("bad").unwrap();
    assert!(
        bad.last_error
            .as_deref()
            .unwrap()
            .contains("boom at iteration 3"),
        "{:?}",
        bad.last_error
    );
    let failing = rt.schema_status("failing").unwrap();
    assert_eq!(failing.last_error.as_deref(), Some("sensor unplugged"));
    let n = count.load(Ordering::Acquire);
    eventually("healthy runs on", || count.load(Ordering::Acquire) > n + 5);
    // A failed schema can be run again.
    rt.run("bad").unwrap();
    eventually("bad stops again", || state(&rt, "bad") == State::Slept);
    rt.shutdown();
}

#[test]
fn cronos_measures_ips() {
    let rt = runtime();
    let count = Arc::new(AtomicU64::new(0));
    rt.add_schema(
        "tenms",
        "",
        Box::new(Counter {
            count: count.clone(),
            ready: Arc::new(AtomicBool::new(true)),
            cycle_ms: 10,
        }),
    )
    .expect("add schema");
    rt.run("tenms").unwrap();
    eventually("iterations", || count.load(Ordering::Acquire) >= 50);
    let s = rt.schema_status("tenms").unwrap();
    // 100 ips nominal; only a sanity range here (timing belongs in benches).
    assert!(
        s.timing.ips > 20.0 && s.timing.ips < 150.0,
        "{}",
        s.timing.ips
    );
    let line = s.ps_line();
    assert!(
        line.starts_with("tenms: ") && line.contains(" ips, winner ()"),
        "{line}"
    );
    rt.shutdown();
}

#[test]
fn interfaces_run_as_children_are_resumed_and_suspended() {
    struct UsesLaser;
    impl Schema for UsesLaser {
        fn on_run(&mut self, ctx: &Context) -> anyhow::Result<()> {
            ctx.run_children(&["laser", "motors"], None)?;
            Ok(())
        }
        fn iteration(&mut self, ctx: &Context) -> anyhow::Result<()> {
            let laser = ctx.interfaces().get::<Laser>("laser")?;
            let _n = laser.read().readings.len();
            Ok(())
        }
    }
    let rt = runtime();
    let laser = rt.interfaces.provide::<Laser>("laser", "test").unwrap();
    let motors = rt.interfaces.provide::<Motors>("motors", "test").unwrap();
    rt.add_schema("user", "", Box::new(UsesLaser))
        .expect("add schema");
    rt.run("user").unwrap();
    eventually("laser resumed", || {
        laser.users() == 1 && motors.users() == 1
    });
    rt.stop("user").unwrap();
    assert_eq!(laser.users(), 0);
    assert_eq!(motors.users(), 0);
    // Running an interface by hand is 4.3's `run laser`.
    rt.run("laser").unwrap();
    assert_eq!(laser.users(), 1);
    rt.stop("laser").unwrap();
    assert!(matches!(rt.stop("laser"), Err(RuntimeError::NotRunning(_))));
    rt.shutdown();
}

#[test]
fn errors_explain() {
    let rt = runtime();
    counter(&rt, "a");
    let e = rt.run("nosuch").unwrap_err().to_string();
    assert!(e.contains("`nosuch` is not loaded; loaded: a"), "{e}");
    rt.interfaces.provide::<Laser>("laser", "t").unwrap();
    let e = rt.show("laser").unwrap_err().to_string();
    assert!(e.contains("only schemas can be shown"), "{e}");
    rt.shutdown();
}

#[test]
fn shutdown_terminates_threads_and_is_idempotent() {
    let rt = runtime();
    let (count, _) = counter(&rt, "a");
    rt.run("a").unwrap();
    eventually("running", || count.load(Ordering::Acquire) > 0);
    rt.shutdown();
    rt.shutdown();
    let n = count.load(Ordering::Acquire);
    std::thread::sleep(Duration::from_millis(20));
    assert_eq!(count.load(Ordering::Acquire), n);
}
