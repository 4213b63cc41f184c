//! The Zenoh session of a conf: `mode`, `listen`, `connect`, `scouting` and a
//! Zenoh config file (ACL, TLS, timeouts: Zenoh's own format, passed through).

use std::path::PathBuf;

use zenoh::{Config, Wait};

use crate::conf::{
    ComponentConf, ConfError,
    settings::{self, Setting, choice, path, rest},
};

/// Batches (64 KiB each) in the transmit queue of frames (`data_low`, the
/// priority images go at; Zenoh's default is 2, the most 16): a 640x480 frame
/// (900 KB) fits whole, so the thread that puts it fills the queue in one go
/// instead of waking the link's writer for every two batches. Set unless a
/// `config` file is given (then the file's value, or Zenoh's default, holds).
pub const FRAME_QUEUE: usize = 16;

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

/// Zenoh's TLS handshake deadline (`tls_handshake_timeout_ms`, Zenoh's default
/// 10 000) set on every `tls/` endpoint the session listens on that does not set
/// its own: a connection that has not finished its handshake by then is closed.
/// With the cap on handshakes in progress (64, vendor/tls-listener patch 0003),
/// strangers that connect and stay silent hold no descriptor for long
/// (docs/zenoh.md, "TLS").
pub const TLS_HANDSHAKE_MS: u64 = 3000;

/// The group of the session's lines in a component's declaration.
pub const GROUP: &str = "session";

/// `mode`: what the session is.
pub const MODE: Setting = Setting::new(
    "mode",
    "peer: talks to peers directly; client: through a router (needs `connect`); router: routes for others",
    &[choice("MODE", &["peer", "client", "router"])],
)
.default("peer")
.group(GROUP);
/// `listen`: endpoints to listen on.
pub const LISTEN: Setting = Setting::new(
    "listen",
    "endpoints it listens on, e.g. tcp/0.0.0.0:7447 (default tcp/127.0.0.1:0: loopback, any port)",
    &[rest("ENDPOINT")],
)
.repeats()
.group(GROUP);
/// `connect`: endpoints to connect to.
pub const CONNECT: Setting = Setting::new(
    "connect",
    "endpoints it connects to, e.g. tcp/10.0.0.2:7447",
    &[rest("ENDPOINT")],
)
.repeats()
.group(GROUP);
/// `scouting`: multicast discovery of peers.
pub const SCOUTING: Setting = Setting::new(
    "scouting",
    "multicast discovery of peers: on loopback only, on the whole LAN, or off",
    &[choice("WHERE", &["loopback", "lan", "off"])],
)
.default("loopback")
.group(GROUP);
/// `config`: a Zenoh config file.
pub const CONFIG: Setting = Setting::new(
    "config",
    "a Zenoh config file (ACL, TLS, timeouts), applied before these lines",
    &[path("FILE.json5")],
)
.group(GROUP);
/// `tls`: Zenoh's TLS transport with mutual authentication.
pub const TLS: Setting = Setting::new(
    "tls",
    "TLS with mutual authentication for tls/ endpoints: the CA that signs every peer's \
     certificate, this side's certificate and its private key (PEM files)",
    &[path("CA.pem"), path("CERT.pem"), path("KEY.pem")],
)
.group(GROUP);
/// `writers`: who may write actuators from the network.
pub const WRITERS: Setting = Setting::new(
    "writers",
    "only peers whose TLS certificate has one of these common names may put values here \
     (motors, pan-tilt, zoom); others may only read (needs `tls`)",
    &[rest("CN")],
)
.group(GROUP);
/// `insecure`, read with the session's lines ([`guard_listen`](settings::guard_listen)
/// reads it too).
pub const INSECURE: Setting = settings::INSECURE.group(GROUP);

/// The values of the session's lines (the group [`GROUP`]: `MODE` .. `WRITERS`
/// and `INSECURE`), read into a component's field with
/// `session: SessionLines = [session::MODE, ..., session::INSECURE]`.
#[derive(serde::Deserialize)]
pub struct SessionLines {
    mode: String,
    listen: Vec<Vec<String>>,
    connect: Vec<Vec<String>>,
    scouting: String,
    #[allow(dead_code)] // read through `existing_file`, which checks it
    config: Option<String>,
    #[allow(dead_code)] // read through `existing_file`, which checks them
    tls: Option<(String, String, String)>,
    writers: Option<Vec<String>>,
    #[allow(dead_code)] // read by `settings::guard_listen`
    insecure: Option<bool>,
}

/// The PEM files of the `tls` line.
#[derive(Clone, Debug, PartialEq)]
pub struct Tls {
    pub ca: PathBuf,
    pub cert: PathBuf,
    pub key: PathBuf,
}

/// The session lines.
#[derive(Clone, Debug, PartialEq)]
pub struct SessionConf {
    pub mode: &'static str,
    pub listen: Vec<String>,
    pub connect: Vec<String>,
    pub scouting: Scouting,
    pub config: Option<PathBuf>,
    /// TLS with mutual authentication (`tls` line).
    pub tls: Option<Tls>,
    /// The certificate common names that may put values here (`writers`); empty:
    /// no access rule.
    pub writers: Vec<String>,
}

impl SessionConf {
    /// The session of `lines` (read from `conf`'s group [`GROUP`]): the
    /// endpoints checked, the files opened, `mode client` and `writers` checked
    /// against the lines they need.
    pub fn new(conf: &ComponentConf, lines: SessionLines) -> Result<SessionConf, ConfError> {
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
        let tls = match conf.line("tls") {
            Some(l) => {
                let pem = |i, what| {
                    let p = l.existing_file(i, what)?;
                    crate::files::open_checked(&p, crate::files::MAX_TEXT_BYTES)
                        .map_err(|e| l.error(format!("`tls`: {e}")))?;
                    Ok::<_, ConfError>(p)
                };
                Some(Tls {
                    ca: pem(0, "the CA certificate")?,
                    cert: pem(1, "this side's certificate")?,
                    key: pem(2, "this side's private key")?,
                })
            }
            None => None,
        };
        let writers: Vec<String> = lines.writers.unwrap_or_default();
        if !writers.is_empty() && tls.is_none() {
            let l = conf.line("writers").expect("writers came from a line");
            return Err(l.error(
                "`writers` names TLS certificates: add a `tls CA.pem CERT.pem KEY.pem` line and \
                 listen on tls/ endpoints",
            ));
        }
        let s = SessionConf {
            mode,
            listen: endpoints("listen", lines.listen)?,
            connect: endpoints("connect", lines.connect)?,
            scouting,
            config,
            tls,
            writers,
        };
        s.guard(conf)?;
        Ok(s)
    }

    /// The suite's rule ([`settings::guard_listen`]): every endpoint this session
    /// listens on or connects to beyond loopback is `tls/` with mutual
    /// authentication, unless the conf says `insecure`. Endpoints set by a
    /// `config` file count too.
    fn guard(&self, conf: &ComponentConf) -> Result<(), ConfError> {
        let c = self.config().map_err(|e| ConfError {
            at: crate::conf::Location {
                file: std::sync::Arc::from(conf.file.as_path()),
                line: 0,
            },
            message: e.to_string(),
        })?;
        let mtls = c
            .get_json("transport/link/tls/enable_mtls")
            .is_ok_and(|v| v.trim() == "true")
            && c.get_json("transport/link/tls/root_ca_certificate")
                .is_ok_and(|v| v.trim() != "null");
        for key in ["listen", "connect"] {
            let json = c.get_json(&format!("{key}/endpoints")).unwrap_or_default();
            let mut all = Vec::new();
            if let Ok(v) = serde_json::from_str::<serde_json::Value>(&json) {
                strings(&v, &mut all);
            }
            for e in all {
                let (proto, addr) = e.split_once('/').unwrap_or(("", &e));
                let hostport = addr.split('#').next().unwrap_or(addr);
                let host = hostport.rsplit_once(':').map_or(hostport, |(h, _)| h);
                settings::guard_listen(
                    conf,
                    key,
                    host,
                    proto == "tls" && mtls,
                    &format!(
                        "`{e}` needs Zenoh's TLS with mutual authentication: use a tls/ endpoint \
                         (`{key} tls/{hostport}`) and a `tls CA.pem CERT.pem KEY.pem` line \
                         (docs/zenoh.md)"
                    ),
                )?;
            }
        }
        Ok(())
    }

    /// The Zenoh config: the file's (or Zenoh's defaults), then these lines. With
    /// neither a file nor `listen` lines a peer listens on loopback only.
    pub fn config(&self) -> anyhow::Result<Config> {
        let mut c = match &self.config {
            // Through the one checked open (a FIFO or /dev/zero named here
            // does not hang or fill memory), then Zenoh's JSON5 parser.
            Some(p) => {
                let text = crate::files::FileError::read(p)
                    .map_err(|e| anyhow::anyhow!("zenoh: the config file {e}"))?;
                Config::from_json5(&text).map_err(|e| {
                    anyhow::anyhow!("zenoh: the config file {} is not valid: {e}", p.display())
                })?
            }
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
        if let Some(t) = &self.tls {
            let file = |p: &PathBuf| serde_json::Value::from(p.display().to_string()).to_string();
            let tls = "transport/link/tls";
            set(&mut c, &format!("{tls}/root_ca_certificate"), file(&t.ca))?;
            set(&mut c, &format!("{tls}/listen_certificate"), file(&t.cert))?;
            set(&mut c, &format!("{tls}/listen_private_key"), file(&t.key))?;
            set(&mut c, &format!("{tls}/connect_certificate"), file(&t.cert))?;
            set(&mut c, &format!("{tls}/connect_private_key"), file(&t.key))?;
            set(&mut c, &format!("{tls}/enable_mtls"), "true".into())?;
        }
        if let Some(v) = handshake_deadlines(&c) {
            set(&mut c, "listen/endpoints", v.to_string())?;
        }
        if !self.writers.is_empty() {
            set(&mut c, "access_control", acl(&self.writers))?;
        }
        if self.config.is_none() {
            set(
                &mut c,
                "transport/link/tx/queue/size/data_low",
                FRAME_QUEUE.to_string(),
            )?;
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

/// Every string in a JSON value (endpoint lists may be per-mode objects).
fn strings(v: &serde_json::Value, out: &mut Vec<String>) {
    match v {
        serde_json::Value::String(s) => out.push(s.clone()),
        serde_json::Value::Array(a) => a.iter().for_each(|x| strings(x, out)),
        serde_json::Value::Object(o) => o.values().for_each(|x| strings(x, out)),
        _ => {}
    }
}

/// The listen endpoints with [`TLS_HANDSHAKE_MS`] on each `tls/` one that sets
/// no deadline of its own (`tls/HOST:PORT#tls_handshake_timeout_ms=3000`, Zenoh's
/// per-endpoint TLS setting); `None` when there is nothing to change.
fn handshake_deadlines(c: &Config) -> Option<serde_json::Value> {
    fn add(v: &mut serde_json::Value) -> bool {
        match v {
            serde_json::Value::String(e)
                if e.starts_with("tls/") && !e.contains("tls_handshake_timeout_ms") =>
            {
                let sep = if e.contains('#') { ';' } else { '#' };
                e.push_str(&format!("{sep}tls_handshake_timeout_ms={TLS_HANDSHAKE_MS}"));
                true
            }
            serde_json::Value::Array(a) => a.iter_mut().map(add).fold(false, |x, y| x | y),
            serde_json::Value::Object(o) => o.values_mut().map(add).fold(false, |x, y| x | y),
            _ => false,
        }
    }
    let json = c.get_json("listen/endpoints").ok()?;
    let mut v = serde_json::from_str(&json).ok()?;
    add(&mut v).then_some(v)
}

/// Zenoh's access control for `writers`: by default nothing is allowed; every
/// peer may subscribe, query, reply and hold liveliness tokens, and this side
/// may put what it publishes; only peers whose certificate's common name is a
/// writer may put (or delete) values here: the actuators a `publishes` side
/// subscribes to.
fn acl(writers: &[String]) -> String {
    let cns: Vec<String> = writers.iter().map(|w| format!("{w:?}")).collect();
    format!(
        r#"{{
  enabled: true,
  default_permission: "deny",
  rules: [
    {{ id: "look", permission: "allow", flows: ["ingress", "egress"], key_exprs: ["**"],
       messages: ["declare_subscriber", "query", "declare_queryable", "reply",
                  "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"] }},
    {{ id: "send", permission: "allow", flows: ["egress"], key_exprs: ["**"],
       messages: ["put", "delete"] }},
    {{ id: "write", permission: "allow", flows: ["ingress"], key_exprs: ["**"],
       messages: ["put", "delete"] }},
  ],
  subjects: [
    {{ id: "anyone", link_protocols: ["tcp", "tls"] }},
    {{ id: "writers", cert_common_names: [{}] }},
  ],
  policies: [
    {{ rules: ["look", "send"], subjects: ["anyone"] }},
    {{ rules: ["look", "send", "write"], subjects: ["writers"] }},
  ],
}}"#,
        cns.join(", ")
    )
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

    crate::declare_lines! {
        struct Only {
            session: SessionLines = [MODE, LISTEN, CONNECT, SCOUTING, CONFIG, TLS, WRITERS, INSECURE],
        }
    }

    fn parse(text: &str) -> Result<SessionConf, ConfError> {
        let conf = ComponentConf::from_text(Kind::Service, "zenoh", text).unwrap();
        let only: Only = conf.read()?;
        SessionConf::new(&conf, only.session)
    }

    #[test]
    fn defaults_are_a_loopback_peer() {
        let s = parse("").unwrap();
        assert_eq!(s.mode, "peer");
        assert_eq!(s.scouting, Scouting::Loopback);
        let c = s.config().unwrap();
        let listen = c.get_json("listen/endpoints").unwrap();
        assert!(listen.contains("tcp/127.0.0.1:0"), "{listen}");
        let q = c.get_json("transport/link/tx/queue/size/data_low").unwrap();
        assert_eq!(q.trim(), FRAME_QUEUE.to_string());
    }

    #[test]
    fn tls_listen_endpoints_get_the_handshake_deadline_unless_they_set_one() {
        let listen = parse("listen tls/127.0.0.1:7447\n")
            .unwrap()
            .config()
            .unwrap();
        let listen = listen.get_json("listen/endpoints").unwrap();
        let v: Vec<String> = serde_json::from_str(&listen).unwrap();
        assert_eq!(
            v,
            [format!(
                "tls/127.0.0.1:7447#tls_handshake_timeout_ms={TLS_HANDSHAKE_MS}"
            )]
        );
        // A config file's endpoint (a conf line's `#` starts a comment) keeps its own.
        let mut c = Config::default();
        let file = r#"["tls/127.0.0.1:7447", "tls/127.0.0.1:7448#tls_handshake_timeout_ms=900",
                       "tcp/127.0.0.1:7449"]"#;
        c.insert_json5("listen/endpoints", file).unwrap();
        let v: Vec<String> = serde_json::from_value(handshake_deadlines(&c).unwrap()).unwrap();
        assert_eq!(
            v,
            [
                format!("tls/127.0.0.1:7447#tls_handshake_timeout_ms={TLS_HANDSHAKE_MS}"),
                "tls/127.0.0.1:7448#tls_handshake_timeout_ms=900".into(),
                "tcp/127.0.0.1:7449".into(),
            ]
        );
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

    #[test]
    fn beyond_loopback_needs_mutual_tls_or_insecure() {
        for text in ["listen tcp/0.0.0.0:7447", "connect tcp/10.0.0.2:7447"] {
            let e = parse(text).unwrap_err().to_string();
            assert!(
                e.contains("beyond loopback") && e.contains("tls CA.pem") && e.contains("insecure"),
                "{e}"
            );
        }
        // A tls/ endpoint without the `tls` line is not mutual authentication.
        let e = parse("listen tls/0.0.0.0:7447").unwrap_err().to_string();
        assert!(e.contains("beyond loopback"), "{e}");
        assert!(parse("listen tcp/0.0.0.0:7447\ninsecure").is_ok());
        assert!(parse("listen tcp/127.0.0.1:7447\nconnect tcp/localhost:7447").is_ok());
        let e = parse("writers operator").unwrap_err().to_string();
        assert!(e.contains("tls CA.pem"), "{e}");
    }
}
