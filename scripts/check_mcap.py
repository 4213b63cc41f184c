#!/usr/bin/env python3
"""Reads a jderobot MCAP recording with the Python `mcap` package (PyPI), the way
a notebook would, and checks it against the documented schemas:

- protobuf channels (foxglove.RawImage, foxglove.CompressedImage,
  foxglove.LaserScan): the schema data is a FileDescriptorSet whose message has
  Foxglove's fields (those of the `foxglove-schemas-protobuf` classes: name,
  number, type, recursively); every message parses with Foxglove's own protobuf class AND with the
  class `mcap-protobuf-support`'s DecoderFactory builds from the file's schema,
  to the same message, with no field the schema does not declare;
- JSON channels: every message validates against its channel's JSON schema
  (`jsonschema`); foxglove.PoseInFrame matches Foxglove's definition: every field
  present, with the JSON type its protobuf type maps to (Foxglove's JSON encoding:
  Timestamp as {sec, nsec}); `clock` is the MCAP message sequence;
- every timestamp is the message's log time, sequences (clocks) increase;
- a laser scan decodes (ranges in m, whole mm; the resolution from the angles)
  and an image decodes (bgr8, width*height*3 bytes, step = width*3).

Prints one JSON line: {"channels": {topic: count}, "laser0": [mm...],
"resolution0": readings/deg, "image0": {"width", "height", "sum"}}; exits 1 with a
message on any problem.

Usage: check_mcap.py FILE.mcap  (inside the venv that .ci/run makes:
target/py-venv, pip: mcap mcap-protobuf-support jsonschema foxglove-schemas-protobuf)
"""

import json
import math
import sys

import jsonschema
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from google.protobuf import unknown_fields
from google.protobuf.descriptor import FieldDescriptor as FD
from google.protobuf.descriptor_pb2 import FileDescriptorSet
from google.protobuf.descriptor_pool import DescriptorPool
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame

# Foxglove's classes of the protobuf channels, and the definitions JSON channels follow.
PROTOBUF = {c.DESCRIPTOR.full_name: c for c in (RawImage, CompressedImage, LaserScan)}
FOXGLOVE = {"foxglove.PoseInFrame": PoseInFrame.DESCRIPTOR}
NUMBERS = {FD.TYPE_DOUBLE, FD.TYPE_FLOAT, FD.TYPE_INT32, FD.TYPE_INT64,
           FD.TYPE_UINT32, FD.TYPE_UINT64, FD.TYPE_FIXED32, FD.TYPE_FIXED64,
           FD.TYPE_SINT32, FD.TYPE_SINT64, FD.TYPE_SFIXED32, FD.TYPE_SFIXED64}


def fail(msg):
    print(f"check_mcap: {msg}", file=sys.stderr)
    sys.exit(1)


def check_value(where, field, value):
    if field.type == FD.TYPE_MESSAGE:
        if field.message_type.full_name == "google.protobuf.Timestamp":
            if not (isinstance(value, dict) and isinstance(value.get("sec"), int)
                    and isinstance(value.get("nsec"), int)):
                fail(f"{where}: a Timestamp must be {{sec, nsec}}, got {value!r}")
            return
        check_message(where, field.message_type, value)
    elif field.type == FD.TYPE_STRING:
        if not isinstance(value, str):
            fail(f"{where}: expected a string")
    elif field.type in NUMBERS:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            fail(f"{where}: expected a number, got {value!r}")
    elif field.type == FD.TYPE_BOOL:
        if not isinstance(value, bool):
            fail(f"{where}: expected a boolean")


def check_message(where, desc, obj):
    if not isinstance(obj, dict):
        fail(f"{where}: expected an object for {desc.full_name}")
    for f in desc.fields:
        if f.name not in obj:
            fail(f"{where}: {desc.full_name} field `{f.name}` is missing")
        v = obj[f.name]
        if f.is_repeated:
            if not isinstance(v, list):
                fail(f"{where}.{f.name}: expected an array")
            for i, x in enumerate(v):
                check_value(f"{where}.{f.name}[{i}]", f, x)
        else:
            check_value(f"{where}.{f.name}", f, v)


def same_fields(where, ours, theirs):
    """Every field of the file's message is Foxglove's (name, number, type,
    repeated), recursively: the file's schema is Foxglove's (a later Foxglove
    release may add fields)."""
    if ours.full_name != theirs.full_name:
        fail(f"{where}: message {ours.full_name}, Foxglove's is {theirs.full_name}")
    if not ours.fields:
        fail(f"{where}: {ours.full_name} has no field in the file's schema")
    for f in ours.fields:
        t = theirs.fields_by_name.get(f.name)
        if t is None or (t.number, t.type, t.is_repeated) != (f.number, f.type, f.is_repeated):
            fail(f"{where}: field {ours.full_name}.{f.name} differs from Foxglove's")
        if f.message_type is not None:
            same_fields(f"{where}.{f.name}", f.message_type, t.message_type)


def check_protobuf(topic, schema, message, decoders):
    """Parses a protobuf message with Foxglove's class and with the class built
    from the file's schema; returns Foxglove's."""
    cls = PROTOBUF.get(schema.name)
    if cls is None or schema.encoding != "protobuf":
        fail(f"{topic}: protobuf schema {schema.name} ({schema.encoding}) is not one of {sorted(PROTOBUF)}")
    if schema.id not in decoders:
        pool = DescriptorPool()
        for fd in FileDescriptorSet.FromString(schema.data).file:
            pool.Add(fd)  # dependencies come first
        same_fields(topic, pool.FindMessageTypeByName(schema.name), cls.DESCRIPTOR)
        decoders[schema.id] = DecoderFactory().decoder_for("protobuf", schema)
    msg = cls.FromString(message.data)
    from_file = decoders[schema.id](message.data)
    if from_file.SerializeToString(deterministic=True) != msg.SerializeToString(deterministic=True):
        fail(f"{topic}: the file's schema and Foxglove's class read the message differently")
    if len(unknown_fields.UnknownFieldSet(msg)) != 0:
        fail(f"{topic}: the message has fields {schema.name} does not declare")
    ts = msg.timestamp.seconds * 1_000_000_000 + msg.timestamp.nanos
    return msg, ts


def main():
    if len(sys.argv) != 2:
        fail("usage: check_mcap.py FILE.mcap")
    counts, out = {}, {}
    validators, decoders, last = {}, {}, {}
    with open(sys.argv[1], "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            topic = channel.topic
            if channel.message_encoding == "protobuf":
                msg, ts = check_protobuf(topic, schema, message, decoders)
            elif channel.message_encoding == "json" and schema.encoding == "jsonschema":
                if schema.id not in validators:
                    validators[schema.id] = jsonschema.Draft202012Validator(json.loads(schema.data))
                msg = json.loads(message.data)
                errors = list(validators[schema.id].iter_errors(msg))
                if errors:
                    fail(f"{topic}: does not validate against {schema.name}: {errors[0].message}")
                if schema.name in FOXGLOVE:
                    check_message(topic, FOXGLOVE[schema.name], msg)
                if msg["clock"] % 2**32 != message.sequence:
                    fail(f"{topic}: clock {msg['clock']} is not the sequence {message.sequence}")
                ts = msg["timestamp"]["sec"] * 1_000_000_000 + msg["timestamp"]["nsec"]
            else:
                fail(f"{topic}: encoding {channel.message_encoding}/{schema.encoding}, expected protobuf or json/jsonschema")
            if ts != message.log_time:
                fail(f"{topic}: timestamp differs from the log time")
            if topic in last and message.sequence <= last[topic]:
                fail(f"{topic}: sequence (clock) {message.sequence} after {last[topic]}")
            last[topic] = message.sequence
            counts[topic] = counts.get(topic, 0) + 1
            if schema.name == "foxglove.LaserScan" and "laser0" not in out:
                mm = [r * 1000 for r in msg.ranges]
                if any(abs(m - round(m)) > 1e-6 for m in mm):
                    fail(f"{topic}: ranges (m) are not whole mm")
                if msg.start_angle != -math.pi / 2 or msg.end_angle <= msg.start_angle:
                    fail(f"{topic}: angles {msg.start_angle}..{msg.end_angle}")
                out["laser0"] = [round(m) for m in mm]
                out["resolution0"] = max(len(mm) - 1, 1) / math.degrees(msg.end_angle - msg.start_angle)
            if schema.name == "foxglove.CompressedImage" and "jpeg0" not in out:
                if msg.format != "jpeg" or msg.data[:2] != b"\xff\xd8":
                    fail(f"{topic}: not a JPEG")
                out["jpeg0"] = len(msg.data)
            if schema.name == "foxglove.RawImage" and "image0" not in out:
                w, h = msg.width, msg.height
                if msg.encoding != "bgr8" or msg.step != w * 3 or len(msg.data) != w * h * 3:
                    fail(f"{topic}: not a {w}x{h} bgr8 image")
                out["image0"] = {"width": w, "height": h, "sum": sum(msg.data)}
    out["channels"] = counts
    print(json.dumps(out))


if __name__ == "__main__":
    main()
