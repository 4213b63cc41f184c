#!/usr/bin/env python3
"""A NAOqi 2.5 stand-in for naobody's tests, on the real libqi (`pip install qi`).

A standalone qi session (its own ServiceDirectory) registers ALMotion,
ALVideoDevice and ALMemory written from Aldebaran's documented NAOqi 2.x API:
the same method names, parameter and return signatures (ALValue is `m`) and
return layouts. It integrates the walk (ALMotion.move in m/s and rad/s;
moveToward normalised), moves the head toward setAngles' targets at the
requested fraction of the joint's speed, and serves a synthetic camera at the
subscribed resolution, colour space and rate.

    naoqi.py --url tcp://127.0.0.1:PORT [--without ALMotion.move] [--bench]
    naoqi.py --url tcp://127.0.0.1:PORT2 --join tcp://127.0.0.1:PORT --without ALMotion.
                                          # services of another process of the robot
    naoqi.py --client tcp://127.0.0.1:PORT --camera 320x240 --seconds 3   # benchmark client

Prints `READY <endpoint>` once listening; with --trace, one line per walk
command (`MOVE x y theta WALLTIME`) and per wakeUp/stopMove (`CALL name`).
"""

import argparse
import math
import sys
import threading
import time

import qi

VERSION = "2.5.5.5"

# ALMotion.getLimits: [min, max, maxVelocity (rad/s), maxTorque (N.m)], NAO V5.
LIMITS = {
    "HeadYaw": [-2.0857, 2.0857, 8.26797, 1.547],
    "HeadPitch": [-0.671952, 0.514872, 7.19407, 1.532],
}
# The walk's own limits (ALMotion.move saturates to them), m/s and rad/s.
MAX_X, MAX_Y, MAX_THETA = 0.1, 0.1, 0.52

# vision_definitions: resolutions and colour spaces.
RESOLUTIONS = {0: (160, 120), 1: (320, 240), 2: (640, 480), 3: (1280, 960), 7: (80, 60), 8: (40, 30)}
K_YUV422, K_RGB, K_BGR = 9, 11, 13

# ALMemory keys (metres for the sonars, 0.0/1.0 for the bumpers).
MEMORY = {
    "Device/SubDeviceList/US/Left/Sensor/Value": 0.8,
    "Device/SubDeviceList/US/Right/Sensor/Value": 1.25,
    "Device/SubDeviceList/LFoot/Bumper/Left/Sensor/Value": 0.0,
    "Device/SubDeviceList/LFoot/Bumper/Right/Sensor/Value": 1.0,
    "Device/SubDeviceList/RFoot/Bumper/Left/Sensor/Value": 0.0,
    "Device/SubDeviceList/RFoot/Bumper/Right/Sensor/Value": 0.0,
}

TRACE = False


def trace(*words):
    if TRACE:
        print(*words, flush=True)


def names_of(v):
    return [v] if isinstance(v, str) else list(v)


class ALMotion:
    def __init__(self):
        self.lock = threading.Lock()
        self.awake = False
        self.pose = [0.0, 0.0, 0.0]  # x, y (m), theta (rad), odometry frame
        self.vel = [0.0, 0.0, 0.0]  # m/s, m/s, rad/s in the robot frame
        self.t = time.monotonic()
        self.head = {"HeadYaw": 0.0, "HeadPitch": 0.0}
        self.target = dict(self.head)
        self.speed = {"HeadYaw": 0.0, "HeadPitch": 0.0}

    def _advance(self):
        now = time.monotonic()
        dt, self.t = now - self.t, now
        x, y, th = self.pose
        vx, vy, w = self.vel
        self.pose = [
            x + (vx * math.cos(th) - vy * math.sin(th)) * dt,
            y + (vx * math.sin(th) + vy * math.cos(th)) * dt,
            math.atan2(math.sin(th + w * dt), math.cos(th + w * dt)),
        ]
        for j in self.head:
            d = self.target[j] - self.head[j]
            step = self.speed[j] * dt
            self.head[j] += max(-step, min(step, d))

    @qi.bind(qi.String, [])
    def version(self):
        return VERSION

    @qi.bind(qi.Void, [])
    def wakeUp(self):
        trace("CALL wakeUp")
        with self.lock:
            self.awake = True

    @qi.bind(qi.Void, [])
    def rest(self):
        with self.lock:
            self._advance()
            self.awake = False
            self.vel = [0.0, 0.0, 0.0]

    @qi.bind(qi.Bool, [])
    def robotIsWakeUp(self):
        return self.awake

    @qi.bind(qi.Void, [qi.Float, qi.Float, qi.Float])
    def move(self, x, y, theta):
        trace("MOVE %.6f %.6f %.6f %.6f" % (x, y, theta, time.time()))
        with self.lock:
            self._advance()
            if not self.awake:
                print("ALMotion.move: the robot is not awake (call wakeUp); ignored", file=sys.stderr, flush=True)
                return
            clamp = lambda v, m: max(-m, min(m, v))
            self.vel = [clamp(x, MAX_X), clamp(y, MAX_Y), clamp(theta, MAX_THETA)]

    @qi.bind(qi.Void, [qi.Float, qi.Float, qi.Float])
    def moveToward(self, x, y, theta):
        clamp = lambda v: max(-1.0, min(1.0, v))
        trace("MOVETOWARD %.6f %.6f %.6f %.6f" % (x, y, theta, time.time()))
        with self.lock:
            self._advance()
            if not self.awake:
                return
            self.vel = [clamp(x) * MAX_X, clamp(y) * MAX_Y, clamp(theta) * MAX_THETA]

    @qi.bind(qi.Void, [])
    def stopMove(self):
        trace("CALL stopMove")
        with self.lock:
            self._advance()
            self.vel = [0.0, 0.0, 0.0]

    @qi.bind(qi.List(qi.Float), [qi.Bool])
    def getRobotPosition(self, use_sensors):
        with self.lock:
            self._advance()
            return list(self.pose)

    @qi.bind(qi.Void, [qi.Dynamic, qi.Dynamic, qi.Float])
    def setAngles(self, names, angles, fraction):
        names = names_of(names)
        angles = [angles] if isinstance(angles, (int, float)) else list(angles)
        with self.lock:
            self._advance()
            if not self.awake:
                return
            for n, a in zip(names, angles):
                if n in LIMITS:
                    lo, hi, vmax, _ = LIMITS[n]
                    self.target[n] = max(lo, min(hi, float(a)))
                    self.speed[n] = max(0.0, min(1.0, fraction)) * vmax

    @qi.bind(qi.List(qi.Float), [qi.Dynamic, qi.Bool])
    def getAngles(self, names, use_sensors):
        with self.lock:
            self._advance()
            return [float(self.head[n]) for n in names_of(names) if n in self.head]

    @qi.bind(qi.Dynamic, [qi.Dynamic])
    def getLimits(self, names):
        return [LIMITS[n] for n in names_of(names) if n in LIMITS]


def bgr_pattern(w, h, k):
    """A BGR test card: the left half red, the right half blue, a green bar
    at column (k * 8) % w; row 0's first pixel's green counts frames."""
    red, blue, green = bytes([0, 0, 255]), bytes([255, 0, 0]), bytes([0, 255, 0])
    bar = (k * 8) % w
    row = bytearray(red * (w // 2) + blue * (w - w // 2))
    row[bar * 3:bar * 3 + 3] = green
    img = bytearray(row * h)
    img[1] = k % 256
    return bytes(img)


def encode(bgr, w, h, cs):
    if cs == K_BGR:
        return bgr, 3
    if cs == K_RGB:
        out = bytearray(bgr)
        out[0::3], out[2::3] = bgr[2::3], bgr[0::3]
        return bytes(out), 3
    if cs == K_YUV422:
        # 0xY'Y'VVYYUU: bytes U Y V Y' per pair of pixels, BT.601 video range.
        out = bytearray(w * h * 2)
        cache = {}
        for i in range(0, w * h, 2):
            p = bgr[i * 3:i * 3 + 6]
            if p not in cache:
                b0, g0, r0, b1, g1, r1 = p

                def y(r, g, b):
                    return round(16 + (65.481 * r + 128.553 * g + 24.966 * b) / 255)
                r, g, b = (r0 + r1) / 2, (g0 + g1) / 2, (b0 + b1) / 2
                u = round(128 + (-37.797 * r - 74.203 * g + 112.0 * b) / 255)
                v = round(128 + (112.0 * r - 93.786 * g - 18.214 * b) / 255)
                cache[p] = bytes([u, y(r0, g0, b0), v, y(r1, g1, b1)])
            out[i * 2:i * 2 + 4] = cache[p]
        return bytes(out), 2
    raise RuntimeError("colour space %d is not served by this stand-in" % cs)


class ALVideoDevice:
    FRAMES = 8

    def __init__(self, bench):
        self.lock = threading.Lock()
        self.subs = {}
        self.cards = {}
        self.bench = bench
        self.calls = 0

    @qi.bind(qi.String, [])
    def version(self):
        return VERSION

    @qi.bind(qi.String, [qi.String, qi.Int32, qi.Int32, qi.Int32, qi.Int32])
    def subscribeCamera(self, name, camera, resolution, colorspace, fps):
        if resolution not in RESOLUTIONS:
            raise RuntimeError("ALVideoDevice.subscribeCamera: unknown resolution %d" % resolution)
        if colorspace not in (K_YUV422, K_RGB, K_BGR):
            raise RuntimeError("ALVideoDevice.subscribeCamera: colour space %d not served here" % colorspace)
        with self.lock:
            handle, i = name, 0
            while handle in self.subs:
                i += 1
                handle = "%s_%d" % (name, i)
            self.subs[handle] = dict(camera=camera, res=resolution, cs=colorspace,
                                     fps=max(1, min(30, fps)), t0=time.time())
            w, h = RESOLUTIONS[resolution]
            key = (w, h, colorspace)
            if key not in self.cards:
                self.cards[key] = [encode(bgr_pattern(w, h, k), w, h, colorspace) for k in range(self.FRAMES)]
        trace("SUBSCRIBE %s" % handle)
        return handle

    @qi.bind(qi.Bool, [qi.String])
    def unsubscribe(self, handle):
        trace("UNSUBSCRIBE %s" % handle)
        with self.lock:
            return self.subs.pop(handle, None) is not None

    @qi.bind(qi.List(qi.String), [])
    def getSubscribers(self):
        with self.lock:
            return list(self.subs)

    # NAOqi declares the reply `m` (an ALValue array holding a binary). libqi-python
    # cannot put a raw buffer inside a dynamic value (it sends bytes as their
    # repr), so the same twelve fields are declared as the struct they are.
    @qi.bind("(iiiiiiriffff)", [qi.String])
    def getImageRemote(self, handle):
        with self.lock:
            s = self.subs.get(handle)
            if s is None:
                raise RuntimeError("ALVideoDevice.getImageRemote: no subscriber %s" % handle)
            w, h = RESOLUTIONS[s["res"]]
            if self.bench:
                self.calls += 1
                k = self.calls
                stamp = s["t0"] + k * 1e-4
            else:
                # The camera gives a new frame every 1/fps s; this is the latest.
                k = int((time.time() - s["t0"]) * s["fps"])
                stamp = s["t0"] + k / s["fps"]
            data, layers = self.cards[(w, h, s["cs"])][k % self.FRAMES]
        sec = int(stamp)
        usec = int((stamp - sec) * 1e6)
        return (w, h, layers, s["cs"], sec, usec, data, s["camera"], 0.52, 0.40, -0.52, -0.40)


class ALMemory:
    @qi.bind(qi.String, [])
    def version(self):
        return VERSION

    @qi.bind(qi.Dynamic, [qi.String])
    def getData(self, key):
        if key not in MEMORY:
            raise RuntimeError("ALMemory.getData: no key %s" % key)
        return MEMORY[key]

    @qi.bind(qi.Dynamic, [qi.Dynamic])
    def getListData(self, keys):
        return [MEMORY.get(k) for k in keys]


def without(cls, methods):
    """The class with some of its methods left out (a robot that lacks them)."""
    keep = {k: v for k, v in cls.__dict__.items()
            if k not in methods and (k == "__init__" or not k.startswith("__"))}
    return type(cls.__name__, (), keep)


def serve(args):
    global TRACE
    TRACE = args.trace
    if args.absurd:
        MEMORY["Device/SubDeviceList/US/Left/Sensor/Value"] = 1e35
        LIMITS["HeadYaw"] = [-1e30, 1e30, 8.26797, 1.547]
    gone = {}
    for w in args.without:
        svc, _, meth = w.partition(".")
        gone.setdefault(svc, set()).add(meth)
    s = qi.Session()
    if args.join:
        # Another process of the same robot: its services register with the
        # ServiceDirectory at --join and are served from their own endpoint.
        s.connect(args.join)
        s.listen(args.url)
    else:
        s.listenStandalone(args.url)
    services = {
        "ALMotion": lambda c: c(),
        "ALVideoDevice": lambda c: c(args.bench),
        "ALMemory": lambda c: c(),
    }
    keep = []
    for name, make in services.items():
        if "" in gone.get(name, ()):
            continue
        cls = {"ALMotion": ALMotion, "ALVideoDevice": ALVideoDevice, "ALMemory": ALMemory}[name]
        obj = make(without(cls, gone.get(name, set())))
        keep.append(obj)
        s.registerService(name, obj)
    print("READY %s" % [e for e in s.endpoints() if e.startswith("tcp://")][0], flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass


def client(args):
    """The benchmark's reference: a Python qi client of the same services."""
    s = qi.Session()
    s.connect(args.client)
    if args.camera:
        w, h = map(int, args.camera.split("x"))
        res = [k for k, v in RESOLUTIONS.items() if v == (w, h)][0]
        video = s.service("ALVideoDevice")
        handle = video.subscribeCamera("pyclient", 0, res, args.colorspace, 30)
        n, last, t0 = 0, None, time.monotonic()
        while time.monotonic() - t0 < args.seconds:
            img = video.getImageRemote(handle)
            if len(img[6]) != w * h * img[2]:
                raise SystemExit("bad frame")
            if (img[4], img[5]) != last:
                n += 1
                last = (img[4], img[5])
        video.unsubscribe(handle)
        print("FPS %.3f" % (n / (time.monotonic() - t0)), flush=True)
    else:
        motion = s.service("ALMotion")
        motion.wakeUp()
        rtts = []
        for i in range(args.count):
            x = 0.001 * (1 + i % 50)
            t0 = time.time()
            motion.move(x, 0.0, 0.0)
            rtts.append(time.time() - t0)
            print("SENT %.6f %.6f" % (x, t0), flush=True)
            time.sleep(0.02)
        rtts.sort()
        print("RTT %.6f" % rtts[len(rtts) // 2], flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--url", default="tcp://127.0.0.1:9559")
    ap.add_argument("--without", action="append", default=[], help="SERVICE.METHOD (or SERVICE.) to leave out")
    ap.add_argument("--join", help="register the services with this ServiceDirectory")
    ap.add_argument("--bench", action="store_true", help="a new frame on every getImageRemote")
    ap.add_argument("--trace", action="store_true")
    ap.add_argument("--absurd", action="store_true",
                    help="a hostile robot: a sonar of 1e35 m, HeadYaw limits of +-1e30 rad")
    ap.add_argument("--client")
    ap.add_argument("--camera")
    ap.add_argument("--colorspace", type=int, default=K_BGR)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--count", type=int, default=200)
    args = ap.parse_args()
    if args.client:
        client(args)
    else:
        serve(args)


if __name__ == "__main__":
    main()
