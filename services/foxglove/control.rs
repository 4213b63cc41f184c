//! What clients do besides watching: subscriptions (which resume the interfaces
//! they need), client publish (a Twist drives `motors`; a jderobot value any served
//! actuator), the services `run`, `stop`, `show` and `hide`, and parameters (what
//! the shell's `echo` prints and `set` writes).

use std::{
    collections::HashMap,
    sync::{
        Arc,
        atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering},
    },
};

use ::foxglove::{
    ChannelId, Schema,
    websocket::{
        AnyClient, ChannelView, Client, ClientChannel, ClientChannelId, ClientId,
        GetParametersResponder, Parameter, ParameterHandler, ParameterValue, ServerListener,
        SetParametersResponder, Status,
        service::{Service, ServiceSchema},
    },
};
use parking_lot::Mutex;
use serde_json::Value;

use crate::{
    interfaces::{
        AnyInterface, Interface, InterfaceValue, Interfaces, Kind, Motors, Watch, with_kind,
    },
    runtime::Runtime,
};

/// Whoever wants one served interface (or the world map).
pub struct Wanted {
    pub iface: Option<Arc<dyn AnyInterface>>,
    /// Subscriptions to its channels, over all clients.
    pub subs: AtomicUsize,
    /// A subscription arrived: send the latest value at once.
    pub greet: AtomicBool,
}

impl Wanted {
    pub fn new(iface: Option<Arc<dyn AnyInterface>>) -> Wanted {
        Wanted {
            iface,
            subs: AtomicUsize::new(0),
            greet: AtomicBool::new(false),
        }
    }
}

/// Client messages refused so far (shown by `ps`).
#[derive(Default)]
pub struct Counters {
    pub commands: AtomicU64,
    pub refused: AtomicU64,
}

/// The server's listener.
pub struct Listener {
    /// Channel id → the entries of `wanted` it gates.
    pub by_channel: HashMap<ChannelId, Vec<usize>>,
    pub wanted: Arc<Vec<Wanted>>,
    /// Served actuators by name.
    pub actuators: HashMap<String, Arc<dyn AnyInterface>>,
    pub rt: Arc<Runtime>,
    /// Which client channel drove which actuator.
    pub drivers: Mutex<HashMap<(ClientId, ClientChannelId), String>>,
    pub wake: Arc<Watch>,
    pub counters: Arc<Counters>,
}

/// The topics a Teleop panel publishes its Twist on, taken for the served `motors`.
const CMD_VEL: &[&str] = &["cmd_vel", "/cmd_vel"];

impl Listener {
    fn gate(&self, channel: &ChannelView, up: bool) {
        let Some(entries) = self.by_channel.get(&channel.id()) else {
            return;
        };
        for &i in entries {
            let w = &self.wanted[i];
            if up {
                if w.subs.fetch_add(1, Ordering::AcqRel) == 0
                    && let Some(i) = &w.iface
                    && !i.is_actuator()
                {
                    i.resume();
                }
                w.greet.store(true, Ordering::Release);
            } else {
                let was = w
                    .subs
                    .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| n.checked_sub(1));
                if was == Ok(1)
                    && let Some(i) = &w.iface
                    && !i.is_actuator()
                {
                    i.suspend();
                }
            }
        }
        self.wake.wake();
    }

    /// The actuator a client topic drives.
    fn target(&self, topic: &str) -> Option<Arc<dyn AnyInterface>> {
        if CMD_VEL.contains(&topic) {
            return self
                .actuators
                .values()
                .find(|i| i.kind() == Kind::Motors)
                .cloned();
        }
        self.actuators.get(topic.trim_start_matches('/')).cloned()
    }

    fn refuse(&self, client: &Client, why: String) {
        self.counters.refused.fetch_add(1, Ordering::Relaxed);
        tracing::debug!("foxglove: refused a client message: {why}");
        client.send_status(Status::error(why));
    }
}

/// A Twist (`geometry_msgs/msg/Twist` as JSON: linear m/s, angular rad/s) or a
/// jderobot `motors` value (`{"v": mm/s, "w": deg/s}`) as [`Motors`].
pub fn motors_from_json(j: &Value) -> Result<Motors, String> {
    let num = |v: Option<&Value>| v.and_then(Value::as_f64).unwrap_or(0.0);
    if j.get("linear").is_some() || j.get("angular").is_some() {
        let (l, a) = (j.get("linear"), j.get("angular"));
        if l.is_some_and(|l| !l.is_object()) || a.is_some_and(|a| !a.is_object()) {
            return Err("a Twist's `linear` and `angular` are objects {x, y, z}".into());
        }
        let v = num(l.and_then(|l| l.get("x"))) * 1000.0;
        let w = num(a.and_then(|a| a.get("z"))).to_degrees();
        return Ok(Motors {
            v: v as f32,
            w: w as f32,
        });
    }
    serde_json::from_value::<Motors>(j.clone()).map_err(|e| {
        format!(
            "expected a Twist {{\"linear\":{{\"x\":m/s}},\"angular\":{{\"z\":rad/s}}}} or a jderobot motors value {{\"v\":mm/s,\"w\":deg/s}}: {e}"
        )
    })
}

fn write_json<T: InterfaceValue + serde::de::DeserializeOwned>(
    interfaces: &Interfaces,
    name: &str,
    j: &Value,
) -> Result<u64, String> {
    let i: Arc<Interface<T>> = interfaces.get(name).map_err(|e| e.to_string())?;
    let v: T = if T::KIND == Kind::Motors {
        let m = motors_from_json(j)?;
        serde_json::from_value(serde_json::json!({"v": m.v, "w": m.w}))
            .map_err(|e| e.to_string())?
    } else {
        serde_json::from_value(j.clone())
            .map_err(|e| format!("not a jderobot {} value: {e}", T::KIND))?
    };
    i.publish(v).map_err(|e| e.to_string())
}

impl ServerListener for Listener {
    fn on_subscribe(&self, _client: Client, channel: ChannelView) {
        self.gate(&channel, true);
    }

    fn on_unsubscribe(&self, _client: Client, channel: ChannelView) {
        self.gate(&channel, false);
    }

    fn on_client_advertise(&self, client: Client, channel: &ClientChannel) {
        if self.target(&channel.topic).is_none() {
            client.send_status(Status::warning(format!(
                "jderobot: topic `{}` drives nothing; publish a Twist on /cmd_vel, or a value on a served actuator's name ({})",
                channel.topic,
                self.actuators.keys().cloned().collect::<Vec<_>>().join(", ")
            )));
        }
    }

    fn on_message_data(&self, client: Client, channel: &ClientChannel, payload: &[u8]) {
        let Some(target) = self.target(&channel.topic) else {
            return self.refuse(
                &client,
                format!("jderobot: topic `{}` drives nothing", channel.topic),
            );
        };
        if channel.encoding != "json" {
            return self.refuse(
                &client,
                format!(
                    "jderobot: `{}` is in encoding `{}`; only json is taken",
                    channel.topic, channel.encoding
                ),
            );
        }
        let j: Value = match serde_json::from_slice(payload) {
            Ok(j) => j,
            Err(e) => {
                return self.refuse(
                    &client,
                    format!("jderobot: `{}`: not JSON: {e}", channel.topic),
                );
            }
        };
        let name = target.name().to_string();
        let r = with_kind!(target.kind(), write_json(&self.rt.interfaces, &name, &j));
        match r {
            Ok(_) => {
                self.counters.commands.fetch_add(1, Ordering::Relaxed);
                self.drivers.lock().insert((client.id(), channel.id), name);
            }
            Err(e) => self.refuse(&client, format!("jderobot: `{}`: {e}", channel.topic)),
        }
    }

    fn on_client_unadvertise(&self, client: Client, channel: &ClientChannel) {
        let Some(name) = self.drivers.lock().remove(&(client.id(), channel.id)) else {
            return;
        };
        if let Ok(m) = self.rt.interfaces.get::<Motors>(&name) {
            let _ = m.publish(Motors::default());
            tracing::info!("foxglove: the client that drove `{name}` left; motors set to zero");
        }
    }
}

/// The JSON schema of a control request: `{"name": "introrob"}`.
fn control_request() -> Vec<u8> {
    serde_json::json!({
        "title": "jderobot.Control",
        "type": "object",
        "properties": {"name": {
            "type": "string",
            "description": "a schema's name (or an interface's, for run/stop)"
        }},
        "required": ["name"]
    })
    .to_string()
    .into_bytes()
}

/// The JSON schema of a control result: `{"ok": true, "message": "stop introrob"}`.
fn control_response() -> Vec<u8> {
    serde_json::json!({
        "title": "jderobot.ControlResult",
        "type": "object",
        "properties": {"ok": {"type": "boolean"}, "message": {"type": "string"}}
    })
    .to_string()
    .into_bytes()
}

/// The name a control request names: `{"name": "introrob"}`, or the bare name.
pub fn control_name(payload: &[u8]) -> Result<String, String> {
    let text = std::str::from_utf8(payload).map_err(|_| "the request is not UTF-8".to_string())?;
    match serde_json::from_str::<Value>(text) {
        Ok(Value::Object(o)) => o
            .get("name")
            .and_then(Value::as_str)
            .map(str::to_string)
            .ok_or_else(|| "expected {\"name\": \"SCHEMA\"}".to_string()),
        Ok(Value::String(s)) => Ok(s),
        _ if !text.trim().is_empty() && !text.contains(char::is_whitespace) => {
            Ok(text.trim().to_string())
        }
        _ => Err("expected {\"name\": \"SCHEMA\"}".into()),
    }
}

/// The services `run`, `stop`, `show` and `hide` (JSON `{"name": ...}` in,
/// `{"ok": true, "message": ...}` out; a failure is the service's error).
pub fn services(rt: &Arc<Runtime>) -> Vec<Service> {
    ["run", "stop", "show", "hide"]
        .into_iter()
        .map(|op| {
            let rt = rt.clone();
            let schema = ServiceSchema::new("jderobot.Control")
                .with_request(
                    "json",
                    Schema::new("jderobot.Control", "jsonschema", control_request()),
                )
                .with_response(
                    "json",
                    Schema::new("jderobot.ControlResult", "jsonschema", control_response()),
                );
            Service::builder(op, schema).blocking_handler_fn(move |req| {
                let name = control_name(req.payload())?;
                let r = match op {
                    "run" => rt.run(&name),
                    "stop" => rt.stop(&name),
                    "show" => rt.show(&name),
                    _ => rt.hide(&name),
                };
                r.map_err(|e| format!("{op}: {e}"))?;
                tracing::info!("foxglove: a client called `{op} {name}`");
                Ok::<_, String>(
                    serde_json::json!({"ok": true, "message": format!("{op} {name}")}).to_string(),
                )
            })
        })
        .collect()
}

/// Parameters: one string parameter per interface, its value as `echo` prints it;
/// setting `NAME.FIELD` (a number or a string) or `NAME` (`"FIELD=VALUE ..."`)
/// writes an actuator's fields as `set NAME FIELD=VALUE` does.
pub struct Params {
    pub rt: Arc<Runtime>,
}

impl Params {
    fn value(&self, name: &str) -> Option<Parameter> {
        let i = self.rt.interfaces.get_any(name).ok()?;
        Some(Parameter::string(
            name,
            format!("clock={} {}", i.clock(), i.describe()),
        ))
    }

    fn set_one(&self, p: &Parameter) -> Result<String, String> {
        let (name, field) = match p.name.split_once('.') {
            Some((n, f)) => (n, Some(f)),
            None => (p.name.as_str(), None),
        };
        let i = self
            .rt
            .interfaces
            .get_any(name)
            .map_err(|e| e.to_string())?;
        if !i.is_actuator() {
            return Err(format!("`{name}` is a sensor; only actuators can be set"));
        }
        let text = |v: &ParameterValue| match v {
            ParameterValue::Integer(n) => Some(n.to_string()),
            ParameterValue::Float64(x) => Some(x.to_string()),
            ParameterValue::String(s) => Some(s.clone()),
            ParameterValue::Bool(b) => Some(b.to_string()),
            _ => None,
        };
        let Some(v) = p.value.as_ref().and_then(text) else {
            return Err(format!("`{}`: give a number or a string", p.name));
        };
        let pairs: Vec<(String, String)> = match field {
            Some(f) => vec![(f.to_string(), v)],
            None => v
                .split_whitespace()
                .map(|kv| {
                    kv.split_once('=')
                        .map(|(k, v)| (k.to_string(), v.to_string()))
                        .ok_or_else(|| format!("`{kv}` is not FIELD=VALUE"))
                })
                .collect::<Result<_, _>>()?,
        };
        let refs: Vec<(&str, &str)> = pairs
            .iter()
            .map(|(k, v)| (k.as_str(), v.as_str()))
            .collect();
        i.set_fields(&refs).map_err(|e| e.to_string())?;
        Ok(name.to_string())
    }
}

impl ParameterHandler for Params {
    fn get(
        &self,
        _client: AnyClient,
        names: Vec<String>,
        _request_id: Option<String>,
        responder: GetParametersResponder,
    ) {
        let names = if names.is_empty() {
            self.rt.interfaces.names()
        } else {
            names
        };
        responder.respond(names.iter().filter_map(|n| self.value(n)).collect());
    }

    fn set(
        &self,
        client: AnyClient,
        parameters: Vec<Parameter>,
        _request_id: Option<String>,
        responder: SetParametersResponder,
    ) {
        let mut done = Vec::new();
        for p in &parameters {
            match self.set_one(p) {
                Ok(name) => done.extend(self.value(&name)),
                Err(e) => {
                    tracing::debug!("foxglove: set {}: {e}", p.name);
                    let _ = &client;
                }
            }
        }
        responder.respond(done);
    }
}
