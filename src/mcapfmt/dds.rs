//! ROS 2 messages on DDS (RustDDS): the CDR bytes of [`super::ros2`], carried as
//! they are. A DataWriter or DataReader of [`Cdr`] with [`CdrAdapter`] sends and
//! receives the one encoder's bytes (the 4-byte encapsulation header is RTPS's
//! own: RustDDS writes it from `output_encoding`), so the service `ros2`, the
//! driver `ros2`, zenoh's `format ros2` and the recorder's `profile ros2` share
//! each message's code.

use std::sync::Arc;

use bytes::Bytes;
use rustdds::{
    QosPolicies, QosPolicyBuilder, RepresentationIdentifier,
    no_key::{Decode, DefaultDecoder, DeserializerAdapter, SerializerAdapter},
    policy::{Durability, History, Reliability},
};

/// A whole little-endian CDR message, its encapsulation header first (what
/// [`super::ros2::encode`] writes and [`super::ros2::decode`] reads). `Bytes`, so
/// that RustDDS sends the encoder's buffer itself (a 640x480 image is 900 KB).
#[derive(Clone, Debug, Default)]
pub struct Cdr(pub Bytes);

/// The buffers of the messages a writer sent, taken back for the next message
/// once RustDDS lets them go (its history keeps the last few). A fresh 900 KB
/// buffer per image cost a page fault per 4 KiB and their zeroing (`clear_page`:
/// 10 % of the samples of `benches/ros2.rs images`, one image per ms).
#[derive(Default)]
pub struct Recycler(Vec<Bytes>);

impl Recycler {
    /// How many sent messages' buffers it keeps (RustDDS's keep-last-5 history,
    /// plus those on their way out).
    const KEPT: usize = 8;

    /// An empty buffer to encode the next message into: a sent message's, when
    /// RustDDS holds it no more.
    pub fn buffer(&mut self) -> Vec<u8> {
        let free = self.0.iter().position(|b| b.is_unique());
        let mut v = match free.map(|i| self.0.swap_remove(i).try_into_mut()) {
            Some(Ok(b)) => Vec::from(b),
            _ => Vec::new(),
        };
        v.clear();
        v
    }

    /// `buf` as a message to write, its buffer kept to be used again.
    pub fn message(&mut self, buf: Vec<u8>) -> Cdr {
        let b = Bytes::from(buf);
        if self.0.len() == Self::KEPT {
            self.0.remove(0);
        }
        self.0.push(b.clone());
        Cdr(b)
    }
}

/// The RustDDS adapter of [`Cdr`].
pub struct CdrAdapter;

/// A message that is not little- or big-endian plain CDR.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct CdrError(String);

impl SerializerAdapter<Cdr> for CdrAdapter {
    type Error = CdrError;
    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }
    fn to_bytes(value: &Cdr) -> Result<Bytes, CdrError> {
        match value.0.get(..2) {
            Some([0, 1]) if value.0.len() >= 4 => Ok(value.0.slice(4..)),
            _ => Err(CdrError("not a little-endian CDR message".into())),
        }
    }
}

const ENCODINGS: [RepresentationIdentifier; 1] = [RepresentationIdentifier::CDR_LE];

impl DeserializerAdapter<Cdr> for CdrAdapter {
    type Error = CdrError;
    type Decoded = Cdr;
    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &ENCODINGS
    }
    fn transform_decoded(decoded: Cdr) -> Cdr {
        decoded
    }
}

/// The decoder: prepends the header the reader of [`super::ros2`] expects.
#[derive(Clone, Copy)]
pub struct CdrDecoder;

impl Decode<Cdr> for CdrDecoder {
    type Error = CdrError;
    fn decode_bytes(
        self,
        input: &[u8],
        encoding: RepresentationIdentifier,
    ) -> Result<Cdr, CdrError> {
        if encoding != RepresentationIdentifier::CDR_LE {
            return Err(CdrError(format!(
                "encoding {encoding:?}: jderobot reads little-endian CDR"
            )));
        }
        let mut v = Vec::with_capacity(input.len() + 4);
        v.extend_from_slice(&[0, 1, 0, 0]);
        v.extend_from_slice(input);
        Ok(Cdr(v.into()))
    }
}

impl DefaultDecoder<Cdr> for CdrAdapter {
    type Decoder = CdrDecoder;
    const DECODER: CdrDecoder = CdrDecoder;
}

/// How far a ROS 2 component's DDS reaches: `localhost` (this host only, as ROS
/// 2's `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`: loopback multicast and
/// addresses, nothing else sent or heard) or `subnet` (every multicast-capable
/// interface). `line` is the component's `discovery` line; without it ROS 2's
/// variables decide, else `subnet`. DDS here has no authentication, so `subnet`
/// starts only when the conf has an `insecure` line; `who` (`driver ros2`) and
/// `does` (`drive it`) name the component and what the line lets it do.
pub fn discovery_range(
    line: Option<&str>,
    insecure: bool,
    who: &str,
    does: &str,
) -> anyhow::Result<Range> {
    let env = |k: &str| std::env::var(k).unwrap_or_default();
    let localhost = match line {
        Some(r) => r == "localhost",
        None => {
            env("ROS_AUTOMATIC_DISCOVERY_RANGE").eq_ignore_ascii_case("localhost")
                || env("ROS_LOCALHOST_ONLY") == "1"
        }
    };
    if !localhost && !insecure {
        anyhow::bail!(
            "{who}: DDS here has no authentication and `discovery subnet` (the default) \
             reaches every multicast interface: anyone on the LAN could read and drive the \
             robot; DDS Security would be needed. Add `discovery localhost` to keep it to \
             this host, or an `insecure` line to {does} on the LAN anyway"
        );
    }
    Ok(Range { localhost })
}

/// A discovery range ([`discovery_range`]).
#[derive(Clone, Copy, Debug)]
pub struct Range {
    pub localhost: bool,
}

/// RustDDS keeps one range per process: the one of the participants alive (the
/// range, how many).
static RANGE_IN_USE: std::sync::Mutex<(bool, usize)> = std::sync::Mutex::new((false, 0));

/// A participant's hold on the process's range, let go when it drops.
struct RangeHold;

impl RangeHold {
    fn take(range: Range, who: &str) -> anyhow::Result<RangeHold> {
        let mut r = RANGE_IN_USE.lock().unwrap_or_else(|e| e.into_inner());
        let name = |l: bool| if l { "localhost" } else { "subnet" };
        if r.1 > 0 && r.0 != range.localhost {
            anyhow::bail!(
                "{who}: `discovery {}`, but another ROS 2 component of this run uses `discovery \
                 {}`: DDS keeps one range per process; give them the same `discovery` line",
                name(range.localhost),
                name(r.0)
            );
        }
        rustdds::set_localhost_only(range.localhost);
        *r = (range.localhost, r.1 + 1);
        Ok(RangeHold)
    }
}

impl Drop for RangeHold {
    fn drop(&mut self) {
        let mut r = RANGE_IN_USE.lock().unwrap_or_else(|e| e.into_inner());
        r.1 = r.1.saturating_sub(1);
    }
}

/// The DDS topic of a ROS 2 topic name: `/scan` → `rt/scan`.
pub fn dds_topic(ros: &str) -> String {
    format!("rt/{}", ros.trim_start_matches('/'))
}

/// A ROS 2 topic name under a namespace: (`/robot1`, `scan`) → `/robot1/scan`;
/// an absolute name (`/tf`) stays as it is.
pub fn ros_topic(namespace: &str, name: &str) -> String {
    if name.starts_with('/') {
        return name.to_string();
    }
    let ns = namespace.trim_end_matches('/');
    format!("{ns}/{name}")
}

/// A ROS 2 node in the graph (ros2-client: `ros2 node list` shows it) and its DDS
/// participant, what the service and the driver `ros2` both start from.
pub struct Graph {
    /// The namespace, with its leading `/`.
    pub ns: String,
    /// The node's name.
    pub name: String,
    pub context: ros2_client::Context,
    pub node: ros2_client::Node,
    pub dp: rustdds::DomainParticipant,
    /// This host only, or the LAN.
    pub range: Range,
    _hold: RangeHold,
}

impl Graph {
    /// Joins DDS domain `domain` within `range` as node `name` in namespace `ns`
    /// (a `/` put in front when missing); `who` (`service ros2`) names the
    /// component in errors.
    pub fn join(
        who: &str,
        range: Range,
        domain: u16,
        ns: &str,
        name: &str,
    ) -> anyhow::Result<Graph> {
        use ros2_client::{Context, ContextOptions, NodeName, NodeOptions};
        let hold = RangeHold::take(range, who)?;
        let ns = if ns.starts_with('/') {
            ns.to_string()
        } else {
            format!("/{ns}")
        };
        let context = Context::with_options(ContextOptions::new().domain_id(domain))
            .map_err(|e| anyhow::anyhow!("{who}: DDS domain {domain}: {e}"))?;
        let node_name = NodeName::new(&ns, name)
            .map_err(|e| anyhow::anyhow!("{who}: node `{name}` in `{ns}`: {e:?}"))?;
        let node = context
            .new_node(node_name, NodeOptions::new())
            .map_err(|e| anyhow::anyhow!("{who}: node: {e:?}"))?;
        let dp = context.domain_participant();
        Ok(Graph {
            ns,
            name: name.to_string(),
            context,
            node,
            dp,
            range,
            _hold: hold,
        })
    }

    /// `ns/name` as the log lines say it.
    pub fn full_name(&self) -> String {
        let sep = if self.ns.ends_with('/') { "" } else { "/" };
        format!("{}{sep}{}", self.ns, self.name)
    }

    /// How far it reaches, for the log lines.
    pub fn reach(&self) -> &'static str {
        if self.range.localhost {
            "this host only"
        } else {
            "the LAN"
        }
    }
}

/// The QoS ROS 2 calls sensor data: best effort, keep last 5, volatile.
pub fn sensor_qos() -> QosPolicies {
    QosPolicyBuilder::new()
        .reliability(Reliability::BestEffort)
        .history(History::KeepLast { depth: 5 })
        .durability(Durability::Volatile)
        .build()
}

/// ROS 2's default QoS: reliable, keep last `depth`, volatile. A write to a
/// slow reliable reader blocks 100 ms at most.
pub fn reliable_qos(depth: i32) -> QosPolicies {
    QosPolicyBuilder::new()
        .reliability(Reliability::Reliable {
            max_blocking_time: rustdds::Duration::from_millis(100),
        })
        .history(History::KeepLast { depth })
        .durability(Durability::Volatile)
        .build()
}

/// `/tf_static`'s QoS: reliable, transient local, keep last 1.
pub fn static_qos() -> QosPolicies {
    QosPolicyBuilder::new()
        .reliability(Reliability::Reliable {
            max_blocking_time: rustdds::Duration::from_millis(100),
        })
        .history(History::KeepLast { depth: 1 })
        .durability(Durability::TransientLocal)
        .build()
}

/// Waits for data on DDS readers (RustDDS's mio event source of each), so a
/// message wakes its thread at once rather than a polling period later; and
/// for its [`Readiness::waker`], so a thread with nothing to read sleeps until
/// it is asked to stop.
pub struct Readiness {
    poll: mio::Poll,
    events: mio::Events,
    count: usize,
    waker: Arc<mio::Waker>,
}

impl Readiness {
    /// `who` (`driver ros2`) names the component in errors.
    pub fn new(who: &str) -> anyhow::Result<Readiness> {
        let poll = mio::Poll::new().map_err(|e| anyhow::anyhow!("{who}: a mio poll: {e}"))?;
        let waker = mio::Waker::new(poll.registry(), mio::Token(0))
            .map_err(|e| anyhow::anyhow!("{who}: a mio waker: {e}"))?;
        Ok(Readiness {
            poll,
            events: mio::Events::with_capacity(16),
            count: 0,
            waker: Arc::new(waker),
        })
    }

    /// Wakes [`Readiness::wait`] from another thread.
    pub fn waker(&self) -> Arc<mio::Waker> {
        self.waker.clone()
    }

    /// Wakes [`Readiness::wait`] when `reader` has data.
    pub fn add<S: mio::event::Source>(&mut self, reader: &mut S) -> anyhow::Result<()> {
        self.count += 1;
        self.poll
            .registry()
            .register(reader, mio::Token(self.count), mio::Interest::READABLE)
            .map_err(|e| anyhow::anyhow!("ros2: watching a reader: {e}"))
    }

    /// Waits until a reader has data, the waker wakes it, or `timeout` (if
    /// any) passes.
    pub fn wait(&mut self, timeout: Option<std::time::Duration>) {
        if self.poll.poll(&mut self.events, timeout).is_err() {
            std::thread::sleep(timeout.unwrap_or(std::time::Duration::from_millis(10)));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_discovery_range_per_process() {
        let (lan, local) = (Range { localhost: false }, Range { localhost: true });
        let a = RangeHold::take(lan, "service ros2").unwrap();
        let e = RangeHold::take(local, "driver ros2")
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("driver ros2") && e.contains("discovery localhost"),
            "{e}"
        );
        assert!(e.contains("discovery subnet"), "{e}");
        let b = RangeHold::take(lan, "driver ros2").unwrap();
        drop((a, b));
        // Once every participant is gone, the next may take the other range.
        drop(RangeHold::take(local, "driver ros2").unwrap());
        rustdds::set_localhost_only(false);
    }

    #[test]
    fn the_lan_needs_insecure_and_localhost_does_not() {
        let e = discovery_range(Some("subnet"), false, "service ros2", "serve it")
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("insecure") && e.contains("discovery localhost"),
            "{e}"
        );
        assert!(discovery_range(Some("subnet"), true, "s", "d").is_ok());
        assert!(
            discovery_range(Some("localhost"), false, "s", "d")
                .unwrap()
                .localhost
        );
    }

    #[test]
    fn a_recycled_buffer_comes_back_once_the_message_is_gone() {
        let mut r = Recycler::default();
        let mut b = r.buffer();
        b.extend_from_slice(&[0, 1, 0, 0, 7, 7]);
        let ptr = b.as_ptr();
        let m = r.message(b);
        assert_eq!(&CdrAdapter::to_bytes(&m).unwrap()[..], &[7, 7]);
        // Still held (RustDDS's history): a new buffer.
        let other = r.buffer();
        assert_ne!(other.as_ptr(), ptr);
        drop(m);
        let again = r.buffer();
        assert_eq!((again.as_ptr(), again.len()), (ptr, 0));
    }
}
