#!/usr/bin/env python3
"""Reads a jderobot MCAP recording with the Python `mcap` package (PyPI), the way
a notebook would, and checks it against the documented schemas:

- every message validates against its channel's JSON schema (`jsonschema`);
- channels named after a Foxglove schema (foxglove.RawImage, foxglove.LaserScan,
  foxglove.PoseInFrame, foxglove.CompressedImage) match Foxglove's own definition, taken from the
  `foxglove-schemas-protobuf` package: every field present, with the JSON type its
  protobuf type maps to (Foxglove's JSON encoding: bytes as base64, Timestamp as
  {sec, nsec});
- a laser scan decodes (ranges in m = the jderobot readings in mm / 1000) and an
  image decodes (base64 bgr8, width*height*3 bytes, step = width*3).

Prints one JSON line: {"channels": {topic: count}, "laser0": [mm...],
"image0": {"width", "height", "sum"}}; exits 1 with a message on any problem.

Usage: check_mcap.py FILE.mcap  (inside the venv that .ci/run makes:
target/py-venv, pip: mcap jsonschema foxglove-schemas-protobuf)
"""

import base64
import json
import sys

import jsonschema
from mcap.reader import make_reader
from google.protobuf.descriptor import FieldDescriptor as FD
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame

FOXGLOVE = {
    "foxglove.RawImage": RawImage.DESCRIPTOR,
    "foxglove.CompressedImage": CompressedImage.DESCRIPTOR,
    "foxglove.LaserScan": LaserScan.DESCRIPTOR,
    "foxglove.PoseInFrame": PoseInFrame.DESCRIPTOR,
}
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
    elif field.type == FD.TYPE_BYTES:
        if not isinstance(value, str):
            fail(f"{where}: bytes must be a base64 string")
        base64.b64decode(value, validate=True)
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


def main():
    if len(sys.argv) != 2:
        fail("usage: check_mcap.py FILE.mcap")
    counts, out = {}, {}
    validators = {}
    with open(sys.argv[1], "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            topic = channel.topic
            if channel.message_encoding != "json" or schema.encoding != "jsonschema":
                fail(f"{topic}: encoding {channel.message_encoding}/{schema.encoding}, expected json/jsonschema")
            if schema.id not in validators:
                validators[schema.id] = jsonschema.Draft202012Validator(json.loads(schema.data))
            msg = json.loads(message.data)
            errors = list(validators[schema.id].iter_errors(msg))
            if errors:
                fail(f"{topic}: does not validate against {schema.name}: {errors[0].message}")
            if schema.name in FOXGLOVE:
                check_message(topic, FOXGLOVE[schema.name], msg)
            ts = msg["timestamp"]
            if ts["sec"] * 1_000_000_000 + ts["nsec"] != message.log_time:
                fail(f"{topic}: timestamp differs from the log time")
            counts[topic] = counts.get(topic, 0) + 1
            if schema.name == "foxglove.LaserScan" and "laser0" not in out:
                mm = msg["jderobot"]["readings"]
                ranges = msg["ranges"]
                if len(ranges) != len(mm) or any(abs(r * 1000 - m) > 1e-6 for r, m in zip(ranges, mm)):
                    fail(f"{topic}: ranges (m) are not the readings (mm) / 1000")
                out["laser0"] = mm
            if schema.name == "foxglove.CompressedImage" and "jpeg0" not in out:
                data = base64.b64decode(msg["data"], validate=True)
                if msg["format"] != "jpeg" or data[:2] != b"\xff\xd8":
                    fail(f"{topic}: not a JPEG")
                out["jpeg0"] = len(data)
            if schema.name == "foxglove.RawImage" and "image0" not in out:
                data = base64.b64decode(msg["data"], validate=True)
                w, h = msg["width"], msg["height"]
                if msg["encoding"] != "bgr8" or msg["step"] != w * 3 or len(data) != w * h * 3:
                    fail(f"{topic}: not a {w}x{h} bgr8 image")
                out["image0"] = {"width": w, "height": h, "sum": sum(data)}
    out["channels"] = counts
    print(json.dumps(out))


if __name__ == "__main__":
    main()
