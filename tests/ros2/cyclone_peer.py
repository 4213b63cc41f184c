"""A ROS 2 peer on Eclipse Cyclone DDS (the `cyclonedds` Python binding), independent
of jderobot's code: its types are the ROS 2 message definitions of
ros2/common_interfaces (sensor_msgs/LaserScan, nav_msgs/Odometry, tf2_msgs/TFMessage,
geometry_msgs/Twist, sensor_msgs/Image, sensor_msgs/Imu, sensor_msgs/Range,
sensor_msgs/JointState, sensor_msgs/CompressedImage) and of irobot/irobot_create_msgs
(HazardDetection, HazardDetectionVector) under the DDS names a ROS 2
node uses (topic `rt/scan`, type `sensor_msgs::msg::dds_::LaserScan_`, ...), written
in XCDR1 as rmw_cyclonedds does.

    cyclone_peer.py listen DOMAIN SECS   subscribe to a served robot, decode every
                                         type field by field, drive it on /cmd_vel
                                         and its pan-tilt on /joint_command
    cyclone_peer.py robot DOMAIN SECS    be a robot: publish /scan and /odom of a
                                         robot in a 10 m square room, move as /cmd_vel says

    cyclone_peer.py bad DOMAIN SECS      publish NaN/inf values, images whose size
                                         disagrees with their data, a wrong type
    cyclone_peer.py many DOMAIN SECS     1,000 endpoints: 500 readers of rt/scan, 500 writers
    cyclone_peer.py camera DOMAIN SECS JPG  publish a JPEG file as a CompressedImage
    cyclone_peer.py clock DOMAIN SECS    read /clock (rclcpp's ClockQoS) and /scan's stamps
    cyclone_peer.py stall DOMAIN SECS    stall reliable readers of /odom and /tf (never
                                         take, room for 1 sample) while sending /cmd_vel
    cyclone_peer.py cmds DOMAIN SECS     read /cmd_vel (a robot base's reliable reader); print
                                         each Twist as it comes: "twist LX AZ"
    cyclone_peer.py frames DOMAIN SECS   read the frame ids of /scan, /odom, /tf, /tf_static,
                                         the camera and /imu
    cyclone_peer.py images DOMAIN SECS   publish a 3x2 image in each 8-bit encoding, rows
                                         padded, on rt/img/ENCODING
    cyclone_peer.py mounted DOMAIN SECS  publish /tf_static base_link -> laser at (0.1 m, 0,
                                         180 deg), a scan from +90 to -90 deg on /scan and
                                         the same scan from -90 to +90 deg on /scan_fwd

Prints one JSON line (but `cmds`).
"""
import json
import math
import os
import sys
import time
import types
from dataclasses import dataclass

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float32, float64, int32, sequence, uint8, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


# The message definitions, as in their .msg files (ros2/common_interfaces,
# ros2/rcl_interfaces, irobot/irobot_create_msgs): `package/Name` and its fields in
# order; `T[]` is a sequence, `T[N]` an array, a bare name a message above it.
MESSAGES = [
    ("builtin_interfaces/Time", "int32 sec, uint32 nanosec"),
    ("std_msgs/Header", "Time stamp, string frame_id"),
    ("sensor_msgs/LaserScan", "Header header, float32 angle_min, float32 angle_max, "
     "float32 angle_increment, float32 time_increment, float32 scan_time, "
     "float32 range_min, float32 range_max, float32[] ranges, float32[] intensities"),
    ("geometry_msgs/Vector3", "float64 x, float64 y, float64 z"),
    ("geometry_msgs/Point", "float64 x, float64 y, float64 z"),
    ("geometry_msgs/Quaternion", "float64 x, float64 y, float64 z, float64 w"),
    ("geometry_msgs/Pose", "Point position, Quaternion orientation"),
    ("geometry_msgs/PoseWithCovariance", "Pose pose, float64[36] covariance"),
    ("geometry_msgs/Twist", "Vector3 linear, Vector3 angular"),
    ("geometry_msgs/TwistWithCovariance", "Twist twist, float64[36] covariance"),
    ("nav_msgs/Odometry", "Header header, string child_frame_id, "
     "PoseWithCovariance pose, TwistWithCovariance twist"),
    ("geometry_msgs/Transform", "Vector3 translation, Quaternion rotation"),
    ("geometry_msgs/TransformStamped", "Header header, string child_frame_id, Transform transform"),
    ("tf2_msgs/TFMessage", "TransformStamped[] transforms"),
    ("sensor_msgs/Image", "Header header, uint32 height, uint32 width, string encoding, "
     "uint8 is_bigendian, uint32 step, uint8[] data"),
    ("sensor_msgs/Imu", "Header header, Quaternion orientation, float64[9] orientation_covariance, "
     "Vector3 angular_velocity, float64[9] angular_velocity_covariance, "
     "Vector3 linear_acceleration, float64[9] linear_acceleration_covariance"),
    ("sensor_msgs/Range", "Header header, uint8 radiation_type, float32 field_of_view, "
     "float32 min_range, float32 max_range, float32 range"),
    ("sensor_msgs/JointState", "Header header, string[] name, float64[] position, "
     "float64[] velocity, float64[] effort"),
    ("sensor_msgs/CompressedImage", "Header header, string format, uint8[] data"),
    ("irobot_create_msgs/HazardDetection", "Header header, uint8 type"),
    ("irobot_create_msgs/HazardDetectionVector", "Header header, HazardDetection[] detections"),
]

PRIMITIVES = {"int32": int32, "uint32": uint32, "uint8": uint8, "float32": float32,
              "float64": float64, "string": str}


def idl_structs(messages):
    """The IdlStruct dataclass of each message, under the DDS name a ROS 2 node
    uses (`sensor_msgs/LaserScan` is `sensor_msgs::msg::dds_::LaserScan_`)."""
    made = {}
    for full, fields in messages:
        package, name = full.split("/")
        annotations = {}
        for field in fields.split(", "):
            typ, field_name = field.split()
            base, _, count = typ.partition("[")
            t = PRIMITIVES.get(base) or made[base]
            if count == "]":
                t = sequence[t]
            elif count:
                t = array[t, int(count[:-1])]
            annotations[field_name] = t
        body = lambda ns, a=annotations: ns.update(__annotations__=a)  # noqa: E731
        typename = f"{package}::msg::dds_::{name}_"
        made[name] = dataclass(types.new_class(name, (IdlStruct,), {"typename": typename}, body))
    return made


# Time, Header, LaserScan, ...: one class per message, under its own name.
globals().update(idl_structs(MESSAGES))


def jpeg_size(data):
    """(width, height) from a JPEG's SOF0..SOF2 segment (ITU T.81 B.2.2), or None."""
    b = bytes(data)
    if b[:2] != b"\xff\xd8":
        return None
    i = 2
    while i + 9 < len(b):
        if b[i] != 0xFF:
            return None
        marker, n = b[i + 1], int.from_bytes(b[i + 2:i + 4], "big")
        if marker in (0xC0, 0xC1, 0xC2):
            return int.from_bytes(b[i + 7:i + 9], "big"), int.from_bytes(b[i + 5:i + 7], "big")
        i += 2 + n
    return None


XCDR1 = Policy.DataRepresentation(use_cdrv0_representation=True)
# rclcpp's defaults: SystemDefaultsQoS / default (reliable, keep last 10, volatile),
# the sensor data profile (best effort, keep last 5), tf_static (transient local).
DEFAULT = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepLast(10),
              Policy.Durability.Volatile, XCDR1)
SENSOR = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5), Policy.Durability.Volatile, XCDR1)
STATIC = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepLast(1),
             Policy.Durability.TransientLocal, XCDR1)


def yaw(q):
    return 2.0 * math.atan2(q.z, q.w)


def listen(dp, secs):
    """A ROS 2 subscriber of every type, each with rclcpp's default QoS for it."""
    readers = {}
    for name, typ, qos in [("scan", LaserScan, SENSOR), ("odom", Odometry, DEFAULT), ("tf", TFMessage, DEFAULT),
                           ("tf_static", TFMessage, STATIC), ("colorA/image_raw", Image, SENSOR),
                           ("imu", Imu, SENSOR), ("sonar_0", Range, SENSOR), ("sonar_15", Range, SENSOR),
                           ("hazard_detection", HazardDetectionVector, SENSOR),
                           ("joint_states", JointState, DEFAULT),
                           ("colorA/image_raw/compressed", CompressedImage, SENSOR)]:
        readers[name] = DataReader(dp, Topic(dp, "rt/" + name, typ, qos=qos), qos=qos)
    cmd = DataWriter(dp, Topic(dp, "rt/cmd_vel", Twist, qos=DEFAULT), qos=DEFAULT)
    joint_cmd = DataWriter(dp, Topic(dp, "rt/joint_command", JointState, qos=DEFAULT), qos=DEFAULT)
    got = {}
    end = time.time() + secs
    odom_first = None
    while time.time() < end:
        if odom_first:  # drive once the starting pose is known
            cmd.write(Twist(Vector3(0.3, 0.0, 0.0), Vector3(0.0, 0.0, 0.2)))
            # pan 0.5 rad at 1 rad/s, tilt -0.3 rad at the unit's speed (no velocity)
            joint_cmd.write(JointState(Header(Time(0, 0), ""), ["pan", "tilt"], [0.5, -0.3], [1.0], []))
        for name, r in readers.items():
            for m in r.take(N=10):
                if name == "scan":
                    got["scan"] = {"frame": m.header.frame_id, "stamp": m.header.stamp.sec, "n": len(m.ranges),
                                   "angle_min": m.angle_min, "angle_max": m.angle_max,
                                   "angle_increment": m.angle_increment, "range_min": m.range_min,
                                   "range_max": m.range_max, "ranges": [m.ranges[0], m.ranges[len(m.ranges) // 2]],
                                   "intensities": len(m.intensities)}
                elif name == "odom":
                    p = m.pose.pose
                    o = {"frame": m.header.frame_id, "child": m.child_frame_id, "x": p.position.x,
                         "y": p.position.y, "yaw": yaw(p.orientation)}
                    odom_first = odom_first or o
                    got["odom_first"] = odom_first
                    got["odom"] = o
                elif name in ("tf", "tf_static"):
                    t = m.transforms[0]
                    got[name] = {"parent": t.header.frame_id, "child": t.child_frame_id,
                                 "x": t.transform.translation.x, "y": t.transform.translation.y,
                                 "yaw": yaw(t.transform.rotation), "n": len(m.transforms)}
                elif name == "colorA/image_raw":
                    got["image"] = {"frame": m.header.frame_id, "width": m.width, "height": m.height,
                                    "encoding": m.encoding, "step": m.step, "bytes": len(m.data),
                                    "big": m.is_bigendian}
                elif name.startswith("sonar_"):
                    got[name] = {"frame": m.header.frame_id, "radiation_type": m.radiation_type,
                                 "field_of_view": m.field_of_view, "min_range": m.min_range,
                                 "max_range": m.max_range, "range": m.range, "stamp": m.header.stamp.sec}
                elif name == "hazard_detection":
                    h = {"frame": m.header.frame_id, "n": len(m.detections),
                         "detections": [{"frame": d.header.frame_id, "type": d.type} for d in m.detections]}
                    got["hazards"] = h
                    if m.detections:
                        got["bumped"] = h
                elif name == "joint_states":
                    got["joints"] = {"name": list(m.name), "position": list(m.position),
                                     "velocity": len(m.velocity), "effort": len(m.effort)}
                elif name == "colorA/image_raw/compressed":
                    size = jpeg_size(m.data)
                    got["compressed"] = {"frame": m.header.frame_id, "format": m.format, "bytes": len(m.data),
                                         "width": size[0] if size else None, "height": size[1] if size else None}
                elif name == "imu":
                    got["imu"] = {"frame": m.header.frame_id, "qw": m.orientation.w,
                                  "az": m.linear_acceleration.z}
        want = ["scan", "odom", "tf", "tf_static", "image", "imu", "sonar_0", "sonar_15", "hazards", "bumped",
                "joints", "compressed"]
        panned = "joints" in got and abs(got["joints"]["position"][0] - 0.5) < 0.02
        moved = "odom" in got and math.hypot(got["odom"]["x"] - got["odom_first"]["x"],
                                             got["odom"]["y"] - got["odom_first"]["y"]) > 0.1
        if all(k in got for k in want) and moved and panned:
            break
        time.sleep(0.05)
    print(json.dumps(got))


def robot(dp, secs):
    """A robot in a 10 m square room (walls at x, y = +-5 m), starting at the
    origin facing +x; it moves as /cmd_vel says (unicycle, 20 Hz)."""
    scan_w = DataWriter(dp, Topic(dp, "rt/scan", LaserScan, qos=SENSOR), qos=SENSOR)
    odom_w = DataWriter(dp, Topic(dp, "rt/odom", Odometry, qos=DEFAULT), qos=DEFAULT)
    # A best-effort reader matches a reliable writer too (as a robot's base does).
    cmd_r = DataReader(dp, Topic(dp, "rt/cmd_vel", Twist, qos=DEFAULT), qos=SENSOR)
    x = y = th = 0.0
    v = w = 0.0
    cmds = 0
    max_v = 0.0
    last_cmd = time.time()
    end = time.time() + secs
    n = 181
    inc = math.pi / 180.0
    zero = [0.0] * 36
    while time.time() < end:
        for m in cmd_r.take(N=20):
            v, w = m.linear.x, m.angular.z
            cmds += 1
            max_v = max(max_v, v)
            last_cmd = time.time()
        if time.time() - last_cmd > 0.5:
            v = w = 0.0
        dt = 0.05
        x += v * math.cos(th) * dt
        y += v * math.sin(th) * dt
        th += w * dt
        ranges = []
        for i in range(n):
            a = th - math.pi / 2 + i * inc
            c, s = math.cos(a), math.sin(a)
            d = min((5.0 - x) / c if c > 1e-9 else 1e9, (-5.0 - x) / c if c < -1e-9 else 1e9,
                    (5.0 - y) / s if s > 1e-9 else 1e9, (-5.0 - y) / s if s < -1e-9 else 1e9)
            ranges.append(min(d, 8.0))
        now = time.time()
        stamp = Time(int(now), int((now % 1) * 1e9))
        scan_w.write(LaserScan(Header(stamp, "base_scan"), -math.pi / 2, math.pi / 2, inc, 0.0, 0.05, 0.12, 8.0,
                               ranges, []))
        q = Quaternion(0.0, 0.0, math.sin(th / 2), math.cos(th / 2))
        odom_w.write(Odometry(Header(stamp, "odom"), "base_footprint",
                              PoseWithCovariance(Pose(Point(x, y, 0.0), q), zero),
                              TwistWithCovariance(Twist(Vector3(v, 0, 0), Vector3(0, 0, w)), zero)))
        time.sleep(dt)
        if cmds > 0 and x > 2.0:
            break
    print(json.dumps({"x": x, "y": y, "theta": th, "cmds": cmds, "max_v": max_v}))


def bad(dp, secs):
    """Publishes what a broken or hostile ROS 2 node might: NaN and infinite
    values, an image whose size disagrees with its data, a CompressedImage that is
    not an image, and an Image on the topic a LaserScan is expected on."""
    scan_w = DataWriter(dp, Topic(dp, "rt/scan", LaserScan, qos=SENSOR), qos=SENSOR)
    odom_w = DataWriter(dp, Topic(dp, "rt/odom", Odometry, qos=DEFAULT), qos=DEFAULT)
    img_w = DataWriter(dp, Topic(dp, "rt/camera/image_raw", Image, qos=SENSOR), qos=SENSOR)
    jpg_w = DataWriter(dp, Topic(dp, "rt/camera/image_raw/compressed", CompressedImage, qos=SENSOR), qos=SENSOR)
    imu_w = DataWriter(dp, Topic(dp, "rt/imu", Imu, qos=SENSOR), qos=SENSOR)
    wrong_w = DataWriter(dp, Topic(dp, "rt/wrong", Image, qos=SENSOR), qos=SENSOR)
    zero = [0.0] * 36
    nine = [0.0] * 9
    nan, inf = float("nan"), float("inf")
    end = time.time() + secs
    n = 0
    while time.time() < end:
        h = Header(Time(int(time.time()), 0), "x")
        scan_w.write(LaserScan(h, nan, 1.0, 0.01, 0.0, 0.0, 0.1, inf, [1.0] * 10, []))
        odom_w.write(Odometry(h, "base", PoseWithCovariance(Pose(Point(nan, 0.0, 0.0),
                                                                  Quaternion(0, 0, 0, 1)), zero),
                              TwistWithCovariance(Twist(Vector3(0, 0, 0), Vector3(0, 0, 0)), zero)))
        img_w.write(Image(h, 480, 640, "bgr8", 0, 1920, [7] * 100))
        jpg_w.write(CompressedImage(h, "jpeg", [0xFF, 0xD8, 0xFF, 0xC0, 0, 17, 8, 0xFF, 0xFF, 0xFF, 0xFF] + [1] * 40))
        imu_w.write(Imu(h, Quaternion(0, 0, 0, inf), nine, Vector3(0, 0, 0), nine, Vector3(0, 0, nan), nine))
        wrong_w.write(Image(h, 1, 1, "bgr8", 0, 3, [0, 0, 0]))
        n += 1
        time.sleep(0.05)
    print(json.dumps({"sent": n}))


def camera(dp, secs, path):
    """Publishes the JPEG file `path` as image_transport's compressed plugin
    does: sensor_msgs/CompressedImage on rt/camera/image_raw/compressed."""
    w = DataWriter(dp, Topic(dp, "rt/camera/image_raw/compressed", CompressedImage, qos=SENSOR), qos=SENSOR)
    data = list(open(path, "rb").read())
    end = time.time() + secs
    n = 0
    while time.time() < end:
        w.write(CompressedImage(Header(Time(int(time.time()), 0), "camera"), "bgr8; jpeg compressed bgr8", data))
        n += 1
        time.sleep(0.05)
    print(json.dumps({"sent": n, "size": jpeg_size(data)}))


@dataclass
class Clock(IdlStruct, typename="rosgraph_msgs::msg::dds_::Clock_"):
    clock: Time


# rclcpp::ClockQoS: best effort, keep last 1 (what use_sim_time's TimeSource reads with).
CLOCK = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(1), Policy.Durability.Volatile, XCDR1)


def clock(dp, secs):
    """Reads rosgraph_msgs/Clock on rt/clock and /scan's header stamps for SECS
    wall seconds after the first Clock."""
    clk = DataReader(dp, Topic(dp, "rt/clock", Clock, qos=CLOCK), qos=CLOCK)
    scan = DataReader(dp, Topic(dp, "rt/scan", LaserScan, qos=SENSOR), qos=SENSOR)
    got = {"n": 0, "backwards": 0}
    end = time.time() + 20
    start = None
    last = None
    while time.time() < end:
        for m in clk.take(N=100):
            t = m.clock.sec + m.clock.nanosec / 1e9
            if start is None:
                start = time.time()
                end = start + secs
                got["first"] = t
            elif t < last:
                got["backwards"] += 1
            last = t
            got["n"] += 1
        for m in scan.take(N=10):
            if last is not None:
                got["scan_stamp"] = m.header.stamp.sec + m.header.stamp.nanosec / 1e9
                got["clock_at_scan"] = last
        time.sleep(0.01)
    got["last"] = last
    got["wall"] = time.time() - start if start else 0
    print(json.dumps(got))


def cmds(dp, secs):
    """A robot base's /cmd_vel reader: each Twist printed as it arrives, at once."""
    cmd_r = DataReader(dp, Topic(dp, "rt/cmd_vel", Twist, qos=DEFAULT), qos=DEFAULT)
    print("ready", flush=True)
    end = time.time() + secs
    while time.time() < end:
        for m in cmd_r.take(N=20):
            print("twist %.4f %.4f" % (m.linear.x, m.angular.z), flush=True)
        time.sleep(0.001)


def stall(dp, secs):
    """A slow reliable subscriber: readers of /odom and /tf with room for one
    sample that never take (DDS flow control then holds the writer back), while
    /cmd_vel Twists go out at 20 Hz: linear.x = K mm/s. Prints when each K was sent."""
    keep1 = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepAll,
                Policy.ResourceLimits(max_samples=1, max_instances=1, max_samples_per_instance=1),
                Policy.Durability.Volatile, XCDR1)
    stalled = [DataReader(dp, Topic(dp, "rt/" + t, typ, qos=DEFAULT), qos=keep1)
               for t, typ in [("odom", Odometry), ("tf", TFMessage)]]
    cmd = DataWriter(dp, Topic(dp, "rt/cmd_vel", Twist, qos=DEFAULT), qos=DEFAULT)
    time.sleep(2.0)  # discovery, and the stalled readers' room filled
    sent = {}
    end = time.time() + secs
    k = 0
    while time.time() < end:
        k += 1
        sent[k] = time.time()
        cmd.write(Twist(Vector3(k / 1000.0, 0.0, 0.0), Vector3(0.0, 0.0, 0.0)))
        time.sleep(0.05)
    print(json.dumps({"sent": sent, "stalled": len(stalled)}), flush=True)
    # Leave at once: the interpreter's teardown of these stalled reliable readers
    # took ~48 s while the service kept writing /odom to them (the test waits for
    # this process to end).
    os._exit(0)


def scans(dp, secs):
    """Reads /scan (sensor QoS) until SECS pass: how many arrived, the seconds
    from the start to the first, and the header stamps (s) of the first and last."""
    r = DataReader(dp, Topic(dp, "rt/scan", LaserScan, qos=SENSOR), qos=SENSOR)
    start = time.time()
    n, first, stamps = 0, None, []
    while time.time() < start + secs:
        for m in r.take(N=10):
            n += 1
            first = first or time.time() - start
            stamps.append(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9)
        time.sleep(0.01)
    print(json.dumps({"scans": n, "first_s": first, "first_stamp": stamps[0] if stamps else None,
                      "last_stamp": stamps[-1] if stamps else None}), flush=True)


def many(dp, secs):
    """1,000 remote endpoints: 500 readers of rt/scan (each a best-effort reader
    the service must match and send to) and 500 writers of topics of their own."""
    readers = [DataReader(dp, Topic(dp, "rt/scan", LaserScan, qos=SENSOR), qos=SENSOR) for _ in range(500)]
    writers = [DataWriter(dp, Topic(dp, "rt/noise_%d" % i, Twist, qos=DEFAULT), qos=DEFAULT) for i in range(500)]
    end = time.time() + secs
    matched = 0
    while time.time() < end:
        for w in writers[:50]:
            w.write(Twist(Vector3(0, 0, 0), Vector3(0, 0, 0)))
        for r in readers:
            matched += len(r.take(N=5))
        time.sleep(0.2)
    print(json.dumps({"readers": len(readers), "writers": len(writers), "matched_scan": matched}))


def frames(dp, secs):
    """Reads the frame ids of /scan, /odom, /tf, /tf_static, the camera and /imu
    (rclcpp's QoS for each) until it has each, SECS at most."""
    topics = [("scan", LaserScan, SENSOR), ("odom", Odometry, DEFAULT), ("tf", TFMessage, DEFAULT),
              ("tf_static", TFMessage, STATIC), ("colorA/image_raw", Image, SENSOR), ("imu", Imu, SENSOR)]
    readers = {n: DataReader(dp, Topic(dp, "rt/" + n, t, qos=q), qos=q) for n, t, q in topics}
    got = {}
    end = time.time() + secs
    while time.time() < end and len(got) < len(readers):
        for name, r in readers.items():
            for m in r.take(N=10):
                if name == "odom":
                    got[name] = [m.header.frame_id, m.child_frame_id]
                elif name.startswith("tf"):
                    got[name] = [[t.header.frame_id, t.child_frame_id] for t in m.transforms]
                else:
                    got[name] = m.header.frame_id
        time.sleep(0.02)
    print(json.dumps(got))


# The pixels of the `images` mode, 3x2, row by row, as (b, g, r).
PIXELS = [(10 * i, 10 * i + 1, 10 * i + 2) for i in range(6)]
# Each encoding's bytes of one (b, g, r) pixel (sensor_msgs/image_encodings.hpp).
ENCODINGS = {"bgr8": lambda b, g, r: [b, g, r], "rgb8": lambda b, g, r: [r, g, b],
             "mono8": lambda b, g, r: [b], "bgra8": lambda b, g, r: [b, g, r, 255],
             "rgba8": lambda b, g, r: [r, g, b, 255]}


def images(dp, secs):
    """Publishes PIXELS in each 8-bit encoding on rt/img/ENCODING (camera drivers'
    sensor QoS), every row padded with 2 bytes of 0xEE, as a driver whose rows
    are aligned does (step = 3 pixels + 2)."""
    writers = {e: DataWriter(dp, Topic(dp, "rt/img/" + e, Image, qos=SENSOR), qos=SENSOR) for e in ENCODINGS}
    end = time.time() + secs
    n = 0
    while time.time() < end:
        for enc, px in ENCODINGS.items():
            rows = []
            for y in range(2):
                row = [v for p in PIXELS[y * 3:y * 3 + 3] for v in px(*p)]
                rows += row + [0xEE, 0xEE]
            step = len(rows) // 2
            writers[enc].write(Image(Header(Time(int(time.time()), 0), "camera"), 2, 3, enc, 0, step, rows))
        n += 1
        time.sleep(0.05)
    print(json.dumps({"sent": n, "pixels": PIXELS}))


def mounted(dp, secs):
    """A lidar that scans clockwise (angle_increment < 0), mounted backwards 10 cm
    ahead of the robot's centre: /tf_static base_link -> laser at (0.1 m, 0 m),
    yaw 180 deg (tf2's static broadcaster: reliable, transient local, sent once),
    /scan from +90 to -90 deg, and on /scan_fwd the same readings from -90 to +90."""
    tf = DataWriter(dp, Topic(dp, "rt/tf_static", TFMessage, qos=STATIC), qos=STATIC)
    tf.write(TFMessage([TransformStamped(Header(Time(int(time.time()), 0), "base_link"), "laser",
                                         Transform(Vector3(0.1, 0.0, 0.0), Quaternion(0.0, 0.0, 1.0, 0.0)))]))
    rev = DataWriter(dp, Topic(dp, "rt/scan", LaserScan, qos=SENSOR), qos=SENSOR)
    fwd = DataWriter(dp, Topic(dp, "rt/scan_fwd", LaserScan, qos=SENSOR), qos=SENSOR)
    inc = math.pi / 180.0
    ccw = [1.0 + i / 100.0 for i in range(181)]  # from -90 deg to +90 deg
    end = time.time() + secs
    n = 0
    while time.time() < end:
        h = Header(Time(int(time.time()), 0), "laser")
        rev.write(LaserScan(h, math.pi / 2, -math.pi / 2, -inc, 0.0, 0.05, 0.1, 8.0, ccw[::-1], []))
        fwd.write(LaserScan(h, -math.pi / 2, math.pi / 2, inc, 0.0, 0.05, 0.1, 8.0, ccw, []))
        n += 1
        time.sleep(0.05)
    print(json.dumps({"sent": n}))


def main():
    mode, domain, secs = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    dp = DomainParticipant(domain)
    if mode == "camera":
        camera(dp, secs, sys.argv[4])
    else:
        {"listen": listen, "robot": robot, "bad": bad, "many": many, "clock": clock,
         "stall": stall, "cmds": cmds, "scans": scans, "frames": frames, "images": images,
         "mounted": mounted}[mode](dp, secs)


if __name__ == "__main__":
    main()
