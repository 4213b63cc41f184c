// Currently, just helpers for mio library

// TODO: Expand this to become an iternal API for polling operations:
// * sockets (send/recv)
// * timers
// * inter-thread channels
//
// Then we cold implement them either on top of mio-0.6, mio-0.8 or something
// else

use std::{
  cmp::Ordering,
  collections::BinaryHeap,
  time::{Duration, Instant},
};

use mio_extras::{timer, timer::Timer};

#[derive(Clone, Copy, Debug, Eq, PartialEq, Ord, PartialOrd)]
pub enum TimerPolicy {
  Repeat,
  OneShot,
}

// The default timer has 256 timer wheel slots and capacity
// ("Max number of timeouts that can be in flight at a given time") of 65536.
// This seems to take up a lot of memory.
// Additionally, each timer creates its own background thread, which also takes
// up resources, but changing that would be a major change.
pub fn new_simple_timer<E>() -> Timer<E> {
  timer::Builder::default().num_slots(4).capacity(2).build()
}

/// jderobot's patch: a timer kept by the thread that polls it, with no thread
/// of its own. mio-extras' `Timer` runs a thread per timer, and the event loop
/// had one per local reader and writer (about 20 for the ros2 service), each
/// waking twice per event (once to fire, once more when re-armed) and the
/// event loop once more: about 60 wake-ups a second of a 180 total
/// (benches/ros2.rs, fan-out CPU). The event loop instead polls with a timeout
/// up to the earliest `next_due` of its timers and runs those due after each
/// poll. Deadlines are exact to the poll's millisecond (mio-extras' ticked at
/// 100 ms, so a 1-ms repair delay was 100 ms).
pub struct LoopTimer<T> {
  due: BinaryHeap<Due<T>>,
  armed: u64,
}

struct Due<T> {
  at: Instant,
  order: u64,
  event: T,
}

impl<T> PartialEq for Due<T> {
  fn eq(&self, other: &Self) -> bool {
    (self.at, self.order) == (other.at, other.order)
  }
}
impl<T> Eq for Due<T> {}
impl<T> PartialOrd for Due<T> {
  fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
    Some(self.cmp(other))
  }
}
impl<T> Ord for Due<T> {
  /// Reversed: the heap's top is the earliest (the first armed of equals).
  fn cmp(&self, other: &Self) -> Ordering {
    (other.at, other.order).cmp(&(self.at, self.order))
  }
}

impl<T> Default for LoopTimer<T> {
  fn default() -> Self {
    Self {
      due: BinaryHeap::new(),
      armed: 0,
    }
  }
}

impl<T> LoopTimer<T> {
  pub fn new() -> Self {
    Self::default()
  }

  /// `event` comes out of `poll` once `delay` has passed. An equal event
  /// already waiting to come out no later is not armed again: a flood of
  /// ACKNACKs asking one reader's repair arms one repair, not one each.
  pub fn set_timeout(&mut self, delay: Duration, event: T)
  where
    T: PartialEq,
  {
    let at = Instant::now() + delay;
    if self.due.iter().any(|d| d.event == event && d.at <= at) {
      return;
    }
    self.armed += 1;
    self.due.push(Due {
      at,
      order: self.armed,
      event,
    });
  }

  /// The earliest event whose time has come, if any.
  pub fn poll(&mut self) -> Option<T> {
    let now = Instant::now();
    if self.due.peek()?.at <= now {
      self.due.pop().map(|d| d.event)
    } else {
      None
    }
  }

  /// When the earliest event is due.
  pub fn next_due(&self) -> Option<Instant> {
    self.due.peek().map(|d| d.at)
  }
}

#[cfg(test)]
mod loop_timer_tests {
  use super::*;

  #[test]
  fn events_come_out_once_due_in_order_of_time_then_of_arming() {
    let mut t = LoopTimer::new();
    t.set_timeout(Duration::from_millis(30), "late");
    t.set_timeout(Duration::ZERO, "first");
    t.set_timeout(Duration::ZERO, "second");
    assert!(t.next_due().unwrap() <= Instant::now());
    assert_eq!(t.poll(), Some("first"));
    assert_eq!(t.poll(), Some("second"));
    assert_eq!(t.poll(), None, "not due yet");
    std::thread::sleep(Duration::from_millis(30));
    assert_eq!(t.poll(), Some("late"));
    assert_eq!((t.poll(), t.next_due()), (None, None));
  }

  #[test]
  fn an_equal_event_waiting_is_not_armed_twice() {
    let mut t = LoopTimer::new();
    for _ in 0..1000 {
      t.set_timeout(Duration::ZERO, "repair");
    }
    t.set_timeout(Duration::from_secs(60), "repair");
    assert_eq!((t.poll(), t.poll()), (Some("repair"), None));
  }
}
