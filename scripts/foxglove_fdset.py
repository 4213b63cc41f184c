#!/usr/bin/env python3
"""Writes assets/foxglove/NAME.fdset: the MCAP `protobuf` schema data of the
Foxglove messages the recorder writes (foxglove.RawImage, foxglove.CompressedImage,
foxglove.LaserScan): a serialized google.protobuf.FileDescriptorSet holding the
message's .proto file and its dependencies, dependencies first.

The descriptors are Foxglove's own, as published in the `foxglove-schemas-protobuf`
PyPI package (MIT), and the set is built by `mcap-protobuf-support`'s
`build_file_descriptor_set`, the way the Python MCAP writer registers a protobuf
schema. jderobot includes the files as they are (src/mcapfmt/protobuf.rs); run this
again only to take a newer Foxglove release.

Usage (in the venv .ci/run makes): python scripts/foxglove_fdset.py
"""

import pathlib

from mcap_protobuf.schema import build_file_descriptor_set
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

OUT = pathlib.Path(__file__).resolve().parent.parent / "assets" / "foxglove"

for message in (RawImage, CompressedImage, LaserScan):
    name = message.DESCRIPTOR.name
    data = build_file_descriptor_set(message).SerializeToString(deterministic=True)
    (OUT / f"{name}.fdset").write_bytes(data)
    print(f"{OUT / name}.fdset: {message.DESCRIPTOR.full_name}, {len(data)} bytes")
