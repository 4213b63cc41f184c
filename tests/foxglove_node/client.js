// The official Foxglove WebSocket client (@foxglove/ws-protocol 0.8.0, on `ws`)
// against a jderobot `foxglove` service, as a user's tooling would use it.
//
//   node client.js ws://127.0.0.1:PORT
//
// It connects (subprotocol foxglove.websocket.v1, the only one this client
// offers), lists the channels with their schemas, subscribes to the laser, the
// encoders, /tf, colorA and world, decodes each with its advertised schema
// (protobufjs from the FileDescriptorSet for protobuf, JSON.parse for json),
// calls the service `stop introrob`, reads the `encoders` parameter, publishes a
// Twist on /cmd_vel for 1.5 s, then leaves. One JSON report on stdout; a failure
// exits 1 with the reason on stderr.
"use strict";

const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");

const url = process.argv[2];
if (!url) {
  console.error("usage: node client.js ws://HOST:PORT");
  process.exit(2);
}

const report = {
  protocol: null,
  capabilities: [],
  channels: [],
  services: [],
  decoded: {},
  counts: {},
  stop: null,
  parameters: null,
  poses: [],
  twists: 0,
};

function fail(why) {
  console.error(`client.js: ${why}`);
  console.log(JSON.stringify(report));
  process.exit(1);
}

const timer = setTimeout(() => fail("timed out (20 s)"), 20000);

const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map(); // id -> { channel, decode }
const services = new Map(); // name -> service
const subs = new Map(); // subscription id -> channel id

function decoderFor(ch) {
  if (ch.encoding === "json") {
    const td = new TextDecoder();
    return (data) => JSON.parse(td.decode(data));
  }
  if (ch.encoding === "protobuf" && ch.schemaEncoding === "protobuf") {
    const bytes = Buffer.from(ch.schema, "base64");
    const set = descriptor.FileDescriptorSet.decode(bytes);
    const root = protobuf.Root.fromDescriptor(set);
    const type = root.lookupType(ch.schemaName);
    return (data) =>
      type.toObject(type.decode(data), { longs: Number, bytes: Buffer, defaults: true });
  }
  throw new Error(`channel ${ch.topic}: cannot decode ${ch.encoding}/${ch.schemaEncoding}`);
}

const want = ["laser", "encoders", "/tf", "colorA", "world", "sonars", "motors"];

client.on("open", () => {
  report.protocol = ws.protocol;
});
client.on("error", (e) => fail(`error: ${e && e.message}`));
client.on("serverInfo", (info) => {
  report.capabilities = info.capabilities;
  report.supportedEncodings = info.supportedEncodings;
});
client.on("status", (s) => {
  (report.statuses = report.statuses || []).push(s.message);
});
client.on("advertise", (list) => {
  for (const ch of list) {
    let decode;
    try {
      decode = decoderFor(ch);
    } catch (e) {
      fail(e.message);
    }
    channels.set(ch.id, { channel: ch, decode });
    report.channels.push({
      topic: ch.topic,
      encoding: ch.encoding,
      schemaName: ch.schemaName,
      schemaEncoding: ch.schemaEncoding,
    });
    if (want.includes(ch.topic)) {
      subs.set(client.subscribe(ch.id), ch.id);
    }
  }
});
client.on("advertiseServices", (list) => {
  for (const s of list) {
    services.set(s.name, s);
    report.services.push(s.name);
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const id = subs.get(subscriptionId);
  const c = channels.get(id);
  if (!c) return;
  const topic = c.channel.topic;
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  let msg;
  try {
    msg = c.decode(bytes);
  } catch (e) {
    fail(`${topic}: message does not decode with its schema ${c.channel.schemaName}: ${e.message}`);
  }
  report.counts[topic] = (report.counts[topic] || 0) + 1;
  if (topic === "encoders") {
    report.poses.push(msg.pose.position);
  }
  if (!(topic in report.decoded)) {
    // Keep small summaries (not the image bytes).
    if (topic === "colorA") {
      report.decoded[topic] = {
        width: msg.width,
        height: msg.height,
        encoding: msg.encoding,
        bytes: msg.data ? msg.data.length : 0,
      };
    } else if (topic === "world") {
      report.decoded[topic] = {
        entities: msg.entities.map((e) => ({
          id: e.id,
          cubes: e.cubes.length,
          spheres: e.spheres.length,
        })),
      };
    } else if (topic === "laser") {
      report.decoded[topic] = {
        frame_id: msg.frame_id,
        start_angle: msg.start_angle,
        end_angle: msg.end_angle,
        ranges: msg.ranges.length,
        first: msg.ranges[0],
      };
    } else {
      report.decoded[topic] = msg;
    }
  }
});

const pending = new Map();
client.on("serviceCallResponse", (r) => {
  const p = pending.get(r.callId);
  if (p) p.resolve(JSON.parse(new TextDecoder().decode(r.data)));
});
client.on("serviceCallFailure", (r) => {
  const p = pending.get(r.callId);
  if (p) p.reject(new Error(r.message));
});
let callId = 1;
function call(name, request) {
  const s = services.get(name);
  if (!s) return Promise.reject(new Error(`no service ${name} (have ${[...services.keys()]})`));
  const id = callId++;
  return new Promise((resolve, reject) => {
    pending.set(id, { resolve, reject });
    client.sendServiceCallRequest({
      serviceId: s.id,
      callId: id,
      encoding: "json",
      data: new Uint8Array(Buffer.from(JSON.stringify(request))),
    });
  });
}

function getParameters(names) {
  return new Promise((resolve) => {
    client.on("parameterValues", (ev) => {
      if (ev.id === "get1") resolve(ev.parameters);
    });
    client.getParameters(names, "get1");
  });
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

async function waitFor(what, f, ms = 10000) {
  const t0 = Date.now();
  while (!f()) {
    if (Date.now() - t0 > ms) fail(`waited ${ms} ms for ${what}`);
    await sleep(20);
  }
}

(async () => {
  await waitFor("the connection", () => report.protocol !== null);
  await waitFor("channels and services", () => channels.size > 0 && services.size > 0);
  // FOXGLOVE_EXPECT (comma-separated topics) for a robot without a world map.
  const expect = (process.env.FOXGLOVE_EXPECT || "laser,encoders,/tf,colorA,world").split(",");
  await waitFor(
    `a message on each of ${expect.join(", ")}`,
    () => expect.every((t) => report.counts[t] > 0),
  );
  report.stop = await call("stop", { name: "introrob" });
  report.parameters = await getParameters(["encoders"]);
  const before = report.poses.length;
  const cmd = client.advertise({
    topic: "/cmd_vel",
    encoding: "json",
    schemaName: "geometry_msgs/msg/Twist",
  });
  const twist = new Uint8Array(
    Buffer.from(JSON.stringify({ linear: { x: 0.3, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } })),
  );
  for (let i = 0; i < 15; i++) {
    client.sendMessage(cmd, twist);
    report.twists++;
    await sleep(100);
  }
  report.posesDuringTwist = report.poses.slice(before);
  // FOXGLOVE_RUN_AGAIN: start introrob again, for the next client (the soak).
  if (process.env.FOXGLOVE_RUN_AGAIN) {
    report.runAgain = await call("run", { name: "introrob" });
  }
  // Leave without unadvertising: the server must zero the motors itself.
  clearTimeout(timer);
  console.log(JSON.stringify(report));
  ws.terminate();
  process.exit(0);
})().catch((e) => fail(e.stack || e.message));
