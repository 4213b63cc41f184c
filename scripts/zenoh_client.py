"""A Python program on a jderobot robot over Zenoh, written from docs/zenoh.md only
(no jderobot code): it reads the laser, an image, the odometry and the imu, decodes them by
the documented byte layouts, and drives `motors` until the robot has moved.

    python scripts/zenoh_client.py jderobot PORT ROBOT   # the jderobot format
    python scripts/zenoh_client.py ros2 PORT ROBOT       # `format ros2`: CDR decoded by rosbags

Connects to tcp/127.0.0.1:PORT. Prints one JSON line with what it saw; exits 1
with the reason when something is missing or wrong.
"""

import json
import math
import os
import struct
import sys
import threading
import time

import zenoh

mode, port, robot = sys.argv[1], int(sys.argv[2]), sys.argv[3]
conf = zenoh.Config()
conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
conf.insert_json5("listen/endpoints", "[]")
conf.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(conf)

latest = {}
lock = threading.Lock()
errors = []


def keep(name):
    def on_sample(sample):
        try:
            value = DECODE[name](sample.payload.to_bytes())
            att = sample.attachment.to_bytes() if sample.attachment is not None else b""
            with lock:
                latest[name] = (value, att, str(sample.encoding))
        except Exception as e:  # noqa: BLE001 - reported at the end
            errors.append(f"{name}: {e!r}")

    return on_sample


def finish(code, message=""):
    """Closes the session and leaves (an open session can keep Python alive)."""
    if message:
        print(message, file=sys.stderr)
    sys.stdout.flush()
    sys.stderr.flush()
    session.close()
    os._exit(code)


def wait_for(names, secs=20):
    end = time.time() + secs
    while time.time() < end:
        with lock:
            if all(n in latest for n in names):
                return
        time.sleep(0.05)
    finish(1, f"no {[n for n in names if n not in latest]} within {secs} s; errors: {errors}")


if mode == "jderobot":
    # docs/zenoh.md: little-endian; attachment = clock u64, time u64 ns.
    def laser(b):
        n, res = struct.unpack_from("<If", b)
        readings = struct.unpack_from(f"<{n}i", b, 8)
        assert len(b) == 8 + 4 * n + 24, "laser size"
        start, min_range, max_range, mx, my, myaw = struct.unpack_from("<6f", b, 8 + 4 * n)
        return {"n": n, "resolution": res, "mm": readings, "start": start, "max_range": max_range}

    def image(b):
        w, h = struct.unpack_from("<II", b)
        assert len(b) == 8 + w * h * 3, "image size"
        return {"w": w, "h": h, "mean": sum(b[8::997]) / len(b[8::997])}

    def encoders(b):
        x, y, theta, c, s = struct.unpack("<5f", b)
        return {"x": x, "y": y, "theta": theta}

    def imu(b):
        qx, qy, qz, qw, wx, wy, wz, ax, ay, az = struct.unpack("<10f", b)
        return {"qz": qz, "qw": qw, "wz": wz, "az": az}

    DECODE = {"laser": laser, "colorA": image, "encoders": encoders, "imu": imu}
    keys = {n: f"jderobot/{robot}/{n}" for n in DECODE}

    def motors(seq, v_mm_s, w_deg_s):
        payload = struct.pack("<ff", v_mm_s, w_deg_s)
        att = struct.pack("<QQ", seq, time.time_ns())
        return payload, att

    motors_key = f"jderobot/{robot}/motors"
    SPEED = 300.0  # mm/s
    pose = lambda e: (e["x"], e["y"])  # noqa: E731
else:
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)

    def ros_key(name, msgtype):
        # rmw_zenoh (Jazzy): <domain>/<topic>/<pkg>::msg::dds_::<Type>_/<RIHS01 hash>
        pkg, _, typ = msgtype.split("/")
        return f"0/{robot}/{name}/{pkg}::msg::dds_::{typ}_/{ts.hash_rihs01(msgtype)}"

    def laser(b):
        m = ts.deserialize_cdr(b, "sensor_msgs/msg/LaserScan")
        return {
            "n": len(m.ranges),
            "angle_min": float(m.angle_min),
            "m": [float(r) for r in m.ranges[:3]],
        }

    def image(b):
        m = ts.deserialize_cdr(b, "sensor_msgs/msg/Image")
        assert len(m.data) == m.step * m.height, "image size"
        return {"w": int(m.width), "h": int(m.height), "encoding": m.encoding}

    def encoders(b):
        m = ts.deserialize_cdr(b, "nav_msgs/msg/Odometry")
        p = m.pose.pose.position
        return {"x": float(p.x) * 1000, "y": float(p.y) * 1000, "frame": m.header.frame_id}

    def imu(b):
        m = ts.deserialize_cdr(b, "sensor_msgs/msg/Imu")
        return {"qz": float(m.orientation.z), "qw": float(m.orientation.w),
                "wz": float(m.angular_velocity.z), "az": float(m.linear_acceleration.z)}

    TYPES = {
        "laser": "sensor_msgs/msg/LaserScan",
        "colorA": "sensor_msgs/msg/Image",
        "encoders": "nav_msgs/msg/Odometry",
        "imu": "sensor_msgs/msg/Imu",
    }
    DECODE = {"laser": laser, "colorA": image, "encoders": encoders, "imu": imu}
    keys = {n: ros_key(n, t) for n, t in TYPES.items()}
    Twist = ts.types["geometry_msgs/msg/Twist"]
    Vector3 = ts.types["geometry_msgs/msg/Vector3"]

    def motors(seq, v_mm_s, w_deg_s):
        t = Twist(
            linear=Vector3(x=v_mm_s / 1000, y=0.0, z=0.0),
            angular=Vector3(x=0.0, y=0.0, z=math.radians(w_deg_s)),
        )
        payload = bytes(ts.serialize_cdr(t, "geometry_msgs/msg/Twist"))
        # rmw_zenoh's attachment: sequence i64, source timestamp i64, gid 16 bytes.
        att = struct.pack("<qq16s", seq, time.time_ns(), b"python-zenoh-gid")
        return payload, att

    motors_key = ros_key("motors", "geometry_msgs/msg/Twist")
    SPEED = 300.0
    pose = lambda e: (e["x"], e["y"])  # noqa: E731


def main():
    subs = [session.declare_subscriber(k, keep(n)) for n, k in keys.items()]
    wait_for(list(DECODE))
    with lock:
        start = pose(latest["encoders"][0])
    # The driving token: when this session ends, the robot zeroes its motors at
    # once instead of after its motors_timeout (docs/zenoh.md, "Keys and presence").
    driving = session.liveliness().declare_token(f"{motors_key}/driven/{session.zid()}")
    publisher = session.declare_publisher(motors_key)
    moved = 0.0
    seq = 0
    end = time.time() + 20
    while time.time() < end and moved < 150.0:
        seq += 1
        payload, att = motors(seq, SPEED, 0.0)
        publisher.put(payload, attachment=att)
        time.sleep(0.1)
        with lock:
            now = pose(latest["encoders"][0])
        moved = math.hypot(now[0] - start[0], now[1] - start[1])
    for _ in range(3):
        payload, att = motors(seq + 1, 0.0, 0.0)
        publisher.put(payload, attachment=att)
        time.sleep(0.05)

    with lock:
        out = {
            "mode": mode,
            "keys": keys,
            "moved_mm": moved,
            "laser": {k: v for k, v in latest["laser"][0].items() if k != "mm"},
            "laser_first_mm": list(latest["laser"][0].get("mm", ())[:3]),
            "image": latest["colorA"][0],
            "image_encoding": latest["colorA"][2],
            "imu": latest["imu"][0],
            "attachment_len": len(latest["laser"][1]),
            "errors": errors,
        }
        if mode == "jderobot":
            clock, t_ns = struct.unpack("<QQ", latest["laser"][1])
            out["laser_clock"] = clock
            out["laser_age_s"] = time.time() - t_ns / 1e9
    print(json.dumps(out))
    if errors or moved < 150.0:
        finish(1, f"moved {moved:.0f} mm; errors: {errors}")
    del subs


try:
    main()
except Exception:  # noqa: BLE001 - any failure ends the session cleanly
    import traceback

    finish(1, traceback.format_exc())
finish(0)
