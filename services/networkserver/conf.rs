//! The networkserver's settings: its declared lines and what they mean.

use std::{
    net::{IpAddr, Ipv4Addr},
    time::Duration,
};

use crate::{
    conf::{
        ComponentConf, ConfLine,
        settings::{self, Setting, int, interface},
    },
    interfaces::{canonical, family},
    netwire,
};

/// The server's settings.
#[derive(Clone, Debug)]
pub struct ServerConf {
    pub bind: IpAddr,
    pub port: u16,
    pub token: Option<String>,
    /// (interface name, network id for images).
    pub serves: Vec<(String, Option<u32>)>,
    pub max_clients: usize,
    pub max_line: usize,
    pub max_queue: usize,
    pub timeout: Duration,
    /// A client with no subscription, no image request waiting, no motors,
    /// pan-tilt or zoom command ever and no line for this long is closed (zero:
    /// never).
    pub idle_timeout: Duration,
}

impl Default for ServerConf {
    fn default() -> Self {
        ServerConf {
            bind: IpAddr::V4(Ipv4Addr::LOCALHOST),
            port: 0,
            token: None,
            serves: Vec::new(),
            max_clients: 128,
            max_line: 1024,
            max_queue: 32,
            timeout: Duration::from_secs(5),
            idle_timeout: Duration::from_secs(60),
        }
    }
}

crate::declare_lines! {
    /// The networkserver's lines, declared once (`jderobot help networkserver`).
    pub(crate) struct Lines {
        socket: Option<u16> = Setting::new(
            "socket",
            "the TCP port it listens on",
            &[int("PORT", "", 0, 65_535)],
        ),
        bind: String = settings::BIND,
        #[allow(dead_code)] // read by `settings::guard_listen`
        insecure: Option<bool> = settings::INSECURE,
        token: Option<String> = settings::TOKEN
            .help("a secret every client must send after its name (`networkclient`'s `token`)"),
        serves: Vec<(String, Option<u32>)> = Setting::new(
            "serves",
            "an interface it serves; images with their network id (0, 1, 2 ...)",
            &[
                interface("NAME"),
                int("NETID", "", 0, u32::MAX as i64).optional(),
            ],
        )
        .repeats(),
        max_clients: usize = Setting::new(
            "max_clients",
            "clients at once; more are refused",
            &[int("N", "", 1, 10_000)],
        )
        .default("128"),
        max_line: usize = Setting::new(
            "max_line",
            "the longest request line",
            &[int("BYTES", "bytes", 64, 1 << 20)],
        )
        .default("1024"),
        max_queue: usize = Setting::new(
            "max_queue",
            "image requests waiting per client; more close it",
            &[int("N", "", 1, 4096)],
        )
        .default("32"),
        timeout: u64 = Setting::new(
            "timeout",
            "how long a client's name, or a blocked write, may take",
            &[int("MS", "ms", 10, 3_600_000)],
        )
        .default("5000"),
        idle_timeout: u64 = Setting::new(
            "idle_timeout",
            "a client that subscribes to nothing and sends nothing this long is closed (0: never)",
            &[int("MS", "ms", 0, 86_400_000)],
        )
        .default("60000"),
    }
}
fn err(l: &ConfLine, m: impl Into<String>) -> anyhow::Error {
    l.error(m).into()
}

impl ServerConf {
    /// Reads the service's lines.
    pub fn parse(conf: &ComponentConf) -> anyhow::Result<ServerConf> {
        let lines: Lines = conf.read()?;
        let mut c = ServerConf {
            max_clients: lines.max_clients,
            max_line: lines.max_line,
            max_queue: lines.max_queue,
            timeout: Duration::from_millis(lines.timeout),
            idle_timeout: Duration::from_millis(lines.idle_timeout),
            ..ServerConf::default()
        };
        c.port = lines.socket.unwrap_or(0);
        let socket = lines.socket.is_some();
        c.bind = lines.bind.parse().map_err(|_| {
            let at = conf.line("bind").map(|l| l.at.to_string()).unwrap_or_default();
            anyhow::anyhow!(
                "{at}: `bind`: `{}` is not an IP address; expected one such as 127.0.0.1 or 0.0.0.0",
                crate::conf::settings::echo(&lines.bind)
            )
        })?;
        c.token = lines.token;
        for (l, (name, id)) in conf.lines_with("serves").zip(lines.serves) {
            let name = canonical(&name);
            let Some(fam) = family(&name) else {
                return Err(err(
                    l,
                    format!("`serves {name}`: no interface kind has that name"),
                ));
            };
            let on_wire = netwire::on_wire(fam);
            let netid = if on_wire == netwire::OnWire::Frames {
                let Some(id) = id else {
                    return Err(err(
                        l,
                        format!(
                            "`serves {name}` needs its network id: serves {name} NETID (0, 1, 2 ...)"
                        ),
                    ));
                };
                if c.serves.iter().any(|(_, n)| *n == Some(id)) {
                    return Err(err(l, format!("network id {id} is served twice")));
                }
                Some(id)
            } else {
                if id.is_some() {
                    return Err(err(l, format!("`serves {name}` takes no network id")));
                }
                if on_wire == netwire::OnWire::Absent {
                    return Err(err(
                        l,
                        format!("4.3's wire has no {fam} message; {fam} cannot be served"),
                    ));
                }
                if c.serves.iter().any(|(n, _)| family(n) == Some(fam)) {
                    return Err(err(
                        l,
                        format!(
                            "a {fam} interface is served twice (4.3's wire has one per server)"
                        ),
                    ));
                }
                None
            };
            c.serves.push((name, netid));
        }
        settings::guard_listen(
            conf,
            "bind",
            &c.bind.to_string(),
            c.token.is_some(),
            "Add a `token SECRET` line (16 to 128 characters) here and the same `token` line to \
             each networkclient",
        )?;
        if !socket {
            return Err(anyhow::anyhow!(
                "{}: networkserver needs a `socket PORT` line in its section",
                conf.file.display()
            ));
        }
        if c.serves.is_empty() {
            tracing::warn!("networkserver: no `serves` line; nothing is served");
        }
        Ok(c)
    }
}
