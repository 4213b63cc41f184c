//! Shared secrets (`token` lines) of the servers and clients that take one
//! (networkserver, networkclient, foxglove): what a token must be, how two are
//! compared, and the back-off that makes guessing one slow.
//!
//! **A token** is [`MIN_TOKEN`] to [`MAX_TOKEN`] printable ASCII characters
//! without spaces ([`check_token`]): a short one is guessed in minutes at
//! thousands of tries a second. `jderobot check` and load refuse a shorter one at
//! its line ([`crate::conf::settings::TOKEN`]).
//!
//! **Back-off per source address** ([`Refusals`]): an address's first
//! [`FREE_TRIES`] wrong (or missing) tokens are only counted; from then on each
//! wrong token makes the server refuse that address's next connections unread for
//! a penalty that doubles from [`FIRST_PENALTY`] up to [`MAX_PENALTY`]. A right
//! token, or [`FORGET_AFTER`] without an attempt, forgets the address. Other
//! addresses are never held, and a refusal costs one table look-up in the accept
//! path (no sleep, no thread). Logging: one line at an address's first wrong
//! token and one per back-off it earns, counting the attempts since the last
//! line: `networkserver: 8403 connections from 10.0.0.2 in 1.0 s without the
//! right token; backing off 2 s`.

use std::{
    collections::HashMap,
    net::IpAddr,
    time::{Duration, Instant},
};

use parking_lot::Mutex;

/// The shortest token accepted.
pub const MIN_TOKEN: usize = 16;
/// The longest token accepted.
pub const MAX_TOKEN: usize = 128;
/// Wrong tokens an address may send before it is backed off.
pub const FREE_TRIES: u32 = 3;
/// The first back-off; each one after doubles it.
pub const FIRST_PENALTY: Duration = Duration::from_secs(1);
/// The longest back-off.
pub const MAX_PENALTY: Duration = Duration::from_secs(60);
/// An address with no attempt for this long starts afresh.
pub const FORGET_AFTER: Duration = Duration::from_secs(600);
/// Addresses remembered at most (the longest quiet is forgotten first).
pub const MAX_ADDRESSES: usize = 4096;

/// Checks a token: [`MIN_TOKEN`] to [`MAX_TOKEN`] printable ASCII characters,
/// no spaces; the error says why.
pub fn check_token(t: &str) -> Result<(), String> {
    if !t.bytes().all(|b| b.is_ascii_graphic()) {
        return Err("a token is printable ASCII without spaces".into());
    }
    if t.len() < MIN_TOKEN {
        return Err(format!(
            "too short: {} characters, at least {MIN_TOKEN} needed, as a short one is guessed \
             by trying; `openssl rand -hex 16` makes a good one",
            t.len()
        ));
    }
    if t.len() > MAX_TOKEN {
        return Err(format!(
            "{} characters; a token has at most {MAX_TOKEN}",
            t.len()
        ));
    }
    Ok(())
}

/// Compares two byte strings in time independent of where they differ.
pub fn same_secret(a: &[u8], b: &[u8]) -> bool {
    let mut d = (a.len() != b.len()) as u8;
    for i in 0..a.len().max(b.len()) {
        d |= a.get(i).copied().unwrap_or(0) ^ b.get(i).copied().unwrap_or(0);
    }
    d == 0
}

/// One address's record.
struct Record {
    /// Wrong tokens since it was last forgotten.
    fails: u32,
    /// Attempts (wrong tokens and refusals) since the last back-off line (or
    /// the first wrong token).
    unsaid: u64,
    /// When that line was written (or that token came).
    said_at: Instant,
    /// Its connections are refused until then.
    until: Option<Instant>,
    /// The last back-off (zero before the first).
    penalty: Duration,
    /// Its last attempt.
    last: Instant,
}

/// The wrong-token back-off of one server, per source address (see the module).
pub struct Refusals {
    who: &'static str,
    table: Mutex<HashMap<IpAddr, Record>>,
}

impl Refusals {
    /// An empty table; `who` names the server in its log lines.
    pub fn new(who: &'static str) -> Refusals {
        Refusals {
            who,
            table: Mutex::new(HashMap::new()),
        }
    }

    /// How much longer `ip` is backed off, if it is: its connection is to be
    /// refused unread (counted for the next log line).
    pub fn holds(&self, ip: IpAddr) -> Option<Duration> {
        let now = Instant::now();
        let mut t = self.table.lock();
        let r = t.get_mut(&ip)?;
        let left = r.until?.checked_duration_since(now)?;
        r.unsaid += 1;
        r.last = now;
        Some(left)
    }

    /// `ip` sent a wrong or missing token: counts it, backs the address off
    /// once it has had its free tries, and logs at most one line.
    pub fn failed(&self, ip: IpAddr) {
        let now = Instant::now();
        let mut t = self.table.lock();
        if t.len() >= MAX_ADDRESSES && !t.contains_key(&ip) {
            t.retain(|_, r| now.duration_since(r.last) < FORGET_AFTER);
            if t.len() >= MAX_ADDRESSES
                && let Some(oldest) = t.iter().min_by_key(|(_, r)| r.last).map(|(a, _)| *a)
            {
                t.remove(&oldest);
            }
        }
        let r = t.entry(ip).or_insert_with(|| Record {
            fails: 0,
            unsaid: 0,
            said_at: now,
            until: None,
            penalty: Duration::ZERO,
            last: now,
        });
        if now.duration_since(r.last) >= FORGET_AFTER {
            (r.fails, r.unsaid, r.penalty, r.until) = (0, 0, Duration::ZERO, None);
        }
        r.fails += 1;
        r.unsaid += 1;
        r.last = now;
        if r.fails == 1 {
            tracing::warn!("{}: a wrong or missing token from {ip}", self.who);
        }
        if r.fails >= FREE_TRIES {
            r.penalty = (r.penalty * 2).clamp(FIRST_PENALTY, MAX_PENALTY);
            r.until = Some(now + r.penalty);
            tracing::warn!(
                "{}: {} connections from {ip} in {:.1} s without the right token; backing off {} s",
                self.who,
                r.unsaid,
                now.duration_since(r.said_at).as_secs_f64(),
                r.penalty.as_secs()
            );
            (r.unsaid, r.said_at) = (0, now);
        }
    }

    /// `ip` sent the right token: forgets its failures.
    pub fn passed(&self, ip: IpAddr) {
        self.table.lock().remove(&ip);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_are_16_to_128_printable_characters() {
        assert!(check_token("0123456789abcdef").is_ok());
        let e = check_token("s").unwrap_err();
        assert!(e.contains("too short") && e.contains("16"), "{e}");
        assert!(check_token("0123456789 abcdef").is_err());
        assert!(check_token(&"x".repeat(129)).is_err());
        assert!(same_secret(b"abc", b"abc") && !same_secret(b"abc", b"abd"));
        assert!(!same_secret(b"abc", b"abcd") && !same_secret(b"", b"a"));
    }

    #[test]
    fn an_address_is_backed_off_after_its_free_tries_and_others_are_not() {
        let r = Refusals::new("test");
        let (a, b): (IpAddr, IpAddr) = ([10, 0, 0, 2].into(), [10, 0, 0, 3].into());
        for _ in 0..FREE_TRIES - 1 {
            r.failed(a);
            assert!(r.holds(a).is_none());
        }
        r.failed(a);
        assert!(r.holds(a).is_some_and(|d| d <= FIRST_PENALTY));
        assert!(r.holds(b).is_none());
        r.failed(a);
        assert!(r.holds(a).is_some_and(|d| d > FIRST_PENALTY));
        r.passed(a);
        assert!(r.holds(a).is_none());
    }
}
