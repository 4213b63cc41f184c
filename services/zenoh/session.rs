//! The Zenoh session of a conf: `mode`, `listen`, `connect`, `scouting` and a
//! Zenoh config file (ACL, TLS, timeouts: Zenoh's own format, passed through).

use std::path::PathBuf;

use zenoh::{Config, Wait};

use crate::conf::{
    ComponentConf, ConfError,
    settings::{Setting, choice, path, rest},
};

/// How multicast scouting finds peers (`scouting` line).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scouting {
    /// On the loopback interface only: processes of this machine find each other.
    Loopback,
    /// On every interface (Zenoh's `auto`): the whole LAN.
    Lan,
    /// None: peers are only those of `connect`/`listen` lines (and their gossip).
    Off,
}

/// `mode`: what the session is.
pub const MODE: Setting = Setting::new(
    "mode",
    "peer: talks to peers directly; client: through a router (needs `connect`); router: routes for others",
    &[choice("MODE", &["peer", "client", "router"])],
)
.default("peer");
/// `listen`: endpoints to listen on.
pub const LISTEN: Setting = Setting::new(
    "listen",
    "endpoints it listens on, e.g. tcp/0.0.0.0:7447 (default tcp/127.0.0.1:0: loopback, any port)",
    &[rest("ENDPOINT")],
)
.repeats();
/// `connect`: endpoints to connect to.
pub const CONNECT: Setting = Setting::new(
    "connect",
    "endpoints it connects to, e.g. tcp/10.0.0.2:7447",
    &[rest("ENDPOINT")],
)
.repeats();
/// `scouting`: multicast discovery of peers.
pub const SCOUTING: Setting = Setting::new(
    "scouting",
    "multicast discovery of peers: on loopback only, on the whole LAN, or off",
    &[choice("WHERE", &["loopback", "lan", "off"])],
)
.default("loopback");
/// `config`: a Zenoh config file.
pub const CONFIG: Setting = Setting::new(
    "config",
    "a Zenoh config file (ACL, TLS, timeouts), applied before these lines",
    &[path("FILE.json5")],
);
/// The session lines, as [`SessionConf::parse`] reads them.
pub const LINES: &[Setting] = &[MODE, LISTEN, CONNECT, SCOUTING, CONFIG];

/// The values of [`LINES`].
#[derive(serde::Deserialize)]
struct Lines {
    mode: String,
    listen: Vec<Vec<String>>,
    connect: Vec<Vec<String>>,
    scouting: String,
    #[allow(dead_code)] // read through `existing_file`, which checks it
    config: Option<String>,
}

/// The session lines.
#[derive(Clone, Debug, PartialEq)]
pub struct SessionConf {
    pub mode: &'static str,
    pub listen: Vec<String>,
    pub connect: Vec<String>,
    pub scouting: Scouting,
    pub config: Option<PathBuf>,
}

impl SessionConf {
    /// Reads `mode`, `listen`, `connect`, `scouting`, `config` ([`LINES`]; later
    /// lines of a single-valued key override earlier ones; listen/connect repeat).
    /// Other lines of `conf` are left to the component.
    pub fn parse(conf: &ComponentConf) -> Result<SessionConf, ConfError> {
        let only = ComponentConf {
            lines: conf
                .lines
                .iter()
                .filter(|l| LINES.iter().any(|s| s.key == l.keyword()))
                .cloned()
                .collect(),
            ..conf.clone()
        };
        let lines: Lines = only.settings(LINES)?;
        let mode = match lines.mode.as_str() {
            "client" => "client",
            "router" => "router",
            _ => "peer",
        };
        let endpoints = |key: &str, words: Vec<Vec<String>>| -> Result<Vec<String>, ConfError> {
            for (l, ws) in conf.lines_with(key).zip(&words) {
                for w in ws {
                    check_endpoint(w).map_err(|e| l.error(format!("`{key}`: {e}")))?;
                }
            }
            Ok(words.into_iter().flatten().collect())
        };
        let scouting = match lines.scouting.as_str() {
            "lan" => Scouting::Lan,
            "off" => Scouting::Off,
            _ => Scouting::Loopback,
        };
        let config = match conf.line("config") {
            Some(l) => Some(l.existing_file(0, "the Zenoh config file")?),
            None => None,
        };
        if mode == "client" && lines.connect.is_empty() && config.is_none() {
            let l = conf.line("mode").expect("mode line read above");
            return Err(
                l.error("`mode client` needs a router to connect to: add `connect tcp/HOST:7447`")
            );
        }
        Ok(SessionConf {
            mode,
            listen: endpoints("listen", lines.listen)?,
            connect: endpoints("connect", lines.connect)?,
            scouting,
            config,
        })
    }

    /// The Zenoh config: the file's (or Zenoh's defaults), then these lines. With
    /// neither a file nor `listen` lines a peer listens on loopback only.
    pub fn config(&self) -> anyhow::Result<Config> {
        let mut c = match &self.config {
            Some(p) => Config::from_file(p).map_err(|e| {
                anyhow::anyhow!("zenoh: the config file {} is not valid: {e}", p.display())
            })?,
            None => Config::default(),
        };
        let set = |c: &mut Config, key: &str, value: String| {
            c.insert_json5(key, &value)
                .map_err(|e| anyhow::anyhow!("zenoh: cannot set {key} to {value}: {e}"))
        };
        set(
            &mut c,
            "mode",
            serde_json::Value::from(self.mode).to_string(),
        )?;
        if !self.listen.is_empty() {
            set(&mut c, "listen/endpoints", json_list(&self.listen))?;
        } else if self.config.is_none() && self.mode != "client" {
            set(
                &mut c,
                "listen/endpoints",
                json_list(&["tcp/127.0.0.1:0".into()]),
            )?;
        }
        if !self.connect.is_empty() {
            set(&mut c, "connect/endpoints", json_list(&self.connect))?;
        }
        if self.config.is_none() || self.scouting != Scouting::Loopback {
            match self.scouting {
                Scouting::Loopback => {
                    set(&mut c, "scouting/multicast/enabled", "true".into())?;
                    set(&mut c, "scouting/multicast/interface", "\"lo\"".into())?;
                }
                Scouting::Lan => {
                    set(&mut c, "scouting/multicast/enabled", "true".into())?;
                    set(&mut c, "scouting/multicast/interface", "\"auto\"".into())?;
                }
                Scouting::Off => set(&mut c, "scouting/multicast/enabled", "false".into())?,
            }
        }
        Ok(c)
    }

    /// Opens the session; the error names the endpoints and the likely fix.
    pub fn open(&self) -> anyhow::Result<zenoh::Session> {
        let config = self.config()?;
        zenoh::open(config).wait().map_err(|e| {
            let all: Vec<String> = self.listen.iter().chain(&self.connect).cloned().collect();
            anyhow::anyhow!(
                "zenoh: cannot open a {} session (listen {}; connect {}): {e}{}{}",
                self.mode,
                list_or_default(&self.listen),
                list_or_default(&self.connect),
                if self.listen.is_empty() {
                    ""
                } else {
                    " (is another process listening on that port?)"
                },
                transport_hint(&all)
            )
        })
    }
}

fn list_or_default(v: &[String]) -> String {
    if v.is_empty() {
        "default".into()
    } else {
        v.join(" ")
    }
}

/// A list of strings as JSON (serde's escaping, which JSON5 reads).
fn json_list(v: &[String]) -> String {
    serde_json::to_string(v).unwrap_or_else(|_| "[]".into())
}

/// An endpoint: `PROTOCOL/HOST:PORT`. TCP is checked here; other transports are
/// Zenoh's to accept (this build carries TCP only, see [`SessionConf::open`]).
fn check_endpoint(e: &str) -> Result<(), String> {
    let (proto, addr) = e.split_once('/').ok_or_else(|| {
        format!("`{e}` is not an endpoint; write PROTOCOL/HOST:PORT, e.g. tcp/127.0.0.1:7447")
    })?;
    let hostport = addr.split('#').next().unwrap_or(addr);
    match hostport.rsplit_once(':') {
        Some((host, port)) if !host.is_empty() && port.parse::<u16>().is_ok() => Ok(()),
        _ => Err(format!(
            "`{e}`: expected {proto}/HOST:PORT, e.g. tcp/127.0.0.1:7447"
        )),
    }
}

/// What to add to an open error when an endpoint is not TCP.
fn transport_hint(endpoints: &[String]) -> String {
    match endpoints.iter().find(|e| !e.starts_with("tcp/")) {
        Some(e) => {
            let proto = e.split('/').next().unwrap_or(e);
            format!(
                "; `{e}`: jderobot's Zenoh carries the tcp transport; for {proto} rebuild with \
                 `cargo build --release --features zenoh,zenoh/transport_{proto}`"
            )
        }
        None => String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::conf::Kind;

    fn parse(text: &str) -> Result<SessionConf, ConfError> {
        SessionConf::parse(&ComponentConf::from_text(Kind::Service, "zenoh", text).unwrap())
    }

    #[test]
    fn defaults_are_a_loopback_peer() {
        let s = parse("").unwrap();
        assert_eq!(s.mode, "peer");
        assert_eq!(s.scouting, Scouting::Loopback);
        let c = s.config().unwrap();
        let listen = c.get_json("listen/endpoints").unwrap();
        assert!(listen.contains("tcp/127.0.0.1:0"), "{listen}");
    }

    #[test]
    fn bad_lines_say_what_is_right() {
        let s = parse("listen udp/127.0.0.1:0").unwrap();
        let e = match s.open() {
            Ok(_) => panic!("udp is not compiled in"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains("zenoh/transport_udp"), "{e}");
        let e = parse("listen tcp/localhost").unwrap_err().to_string();
        assert!(e.contains("tcp/HOST:PORT"), "{e}");
        let e = parse("mode client").unwrap_err().to_string();
        assert!(e.contains("connect tcp/HOST:7447"), "{e}");
        let e = parse("mode boss").unwrap_err().to_string();
        assert!(e.contains("peer, client, router"), "{e}");
    }
}
