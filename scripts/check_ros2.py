#!/usr/bin/env python3
"""Opens a jderobot `profile ros2` recording with the `rosbags` package (PyPI) as a
rosbag2 and decodes its messages with rosbags' own ROS 2 type store (not the
file's schemas): sensor_msgs/msg/LaserScan, sensor_msgs/msg/Image,
sensor_msgs/msg/Imu, nav_msgs/msg/Odometry, geometry_msgs/msg/Twist.

Prints one JSON line: {"connections": {topic: [msgtype, count]},
"laser0": [mm...], "image0": {"width", "height", "encoding", "sum"},
"odom0": [x_mm, y_mm], "imu0": {"qz", "qw", "wz", "az"}}; exits 1 with a message on a problem.

Usage: check_ros2.py FILE.mcap  (venv of .ci/run: target/py-venv, pip: rosbags)
"""

import json
import sys

from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore


def main():
    if len(sys.argv) != 2:
        print("usage: check_ros2.py FILE.mcap", file=sys.stderr)
        sys.exit(1)
    store = get_typestore(Stores.ROS2_HUMBLE)
    out = {"connections": {}}
    with Reader(sys.argv[1]) as reader:
        for c in reader.connections:
            out["connections"][c.topic] = [c.msgtype, c.msgcount]
        for conn, _t, raw in reader.messages():
            msg = store.deserialize_cdr(raw, conn.msgtype)
            if conn.msgtype == "sensor_msgs/msg/LaserScan" and "laser0" not in out:
                out["laser0"] = [round(r * 1000) for r in msg.ranges.tolist()]
            elif conn.msgtype == "sensor_msgs/msg/Image" and "image0" not in out:
                if msg.step != msg.width * 3 or len(msg.data) != msg.width * msg.height * 3:
                    print(f"{conn.topic}: a bad image", file=sys.stderr)
                    sys.exit(1)
                out["image0"] = {"width": msg.width, "height": msg.height,
                                 "encoding": msg.encoding, "sum": int(msg.data.sum())}
            elif conn.msgtype == "sensor_msgs/msg/Imu" and "imu0" not in out:
                o = msg.orientation
                out["imu0"] = {"qz": o.z, "qw": o.w, "wz": msg.angular_velocity.z,
                               "az": msg.linear_acceleration.z}
            elif conn.msgtype == "nav_msgs/msg/Odometry" and "odom0" not in out:
                p = msg.pose.pose.position
                out["odom0"] = [p.x * 1000, p.y * 1000]
    print(json.dumps(out))


if __name__ == "__main__":
    main()
