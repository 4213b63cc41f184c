"""jderobot's helper for python schemas (the module `_jderobot`, internal).

Splits a student's program into the Academy's shape (the code before the first
top-level `while True:` runs once, the loop's body is one iteration), keeping the
program's own file name and line numbers so tracebacks point at the student's lines.
"""
import ast
import sys
import traceback

BROKE = "__jderobot_broke__"


def _forever(test):
    return isinstance(test, ast.Constant) and (
        test.value is True or (type(test.value) is int and test.value != 0)
    )


def _module(body):
    return ast.Module(body=body, type_ignores=[])


# The Academy's modules as a program imports them: `from HAL import HAL` (and
# GUI) is the 4.x shape; `import HAL`, `import GUI`, `import WebGUI`,
# `import Frequency` (or `from HAL import setV`, ...) is the Academy 5 shape.
ACADEMY = ("HAL", "GUI", "WebGUI", "Frequency")


def shape(tree):
    """5 if the program imports the Academy's modules the Academy 5 way (module
    functions, its own loop paced by Frequency.tick), else 4."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            if any(a.name in ACADEMY for a in node.names):
                return 5
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module in ACADEMY:
            if node.module in ("WebGUI", "Frequency"):
                return 5
            if any(a.name != node.module for a in node.names):
                return 5
    return 4


def split(source, path):
    """(init, loop, after, loop_line, shape): code objects; loop and after are
    None without a top-level `while True:` and in the Academy 5 shape (the whole
    program is `init`: its own loop runs). Raises SyntaxError."""
    tree = ast.parse(source, path)
    add_program_dir(path)
    if shape(tree) == 5:
        return compile(tree, path, "exec"), None, None, 0, 5
    body = tree.body
    for i, node in enumerate(body):
        if isinstance(node, ast.While) and _forever(node.test):
            break
    else:
        return compile(tree, path, "exec"), None, None, 0, 4
    # One iteration: `for _ in (0,): BODY else: BROKE = False`, so `continue`
    # ends the iteration and `break` ends the loop, as in the original `while`.
    set_broke = ast.Assign(
        targets=[ast.Name(BROKE, ast.Store())], value=ast.Constant(True)
    )
    clear = ast.Assign(
        targets=[ast.Name(BROKE, ast.Store())], value=ast.Constant(False)
    )
    once = ast.For(
        target=ast.Name("__jderobot_once__", ast.Store()),
        iter=ast.Tuple([ast.Constant(0)], ast.Load()),
        body=node.body,
        orelse=[clear],
        type_comment=None,
    )
    for n in (set_broke, clear, once):
        ast.copy_location(n, node)
    loop = ast.fix_missing_locations(_module([set_broke, once]))
    init = _module(body[:i])
    after = _module(body[i + 1 :])
    return (
        compile(init, path, "exec"),
        compile(loop, path, "exec"),
        compile(after, path, "exec"),
        node.lineno,
        4,
    )


class LaserValues(list):
    """The Academy 5 `HAL.getLaserData()`: the ranges in m (a list, as the vacuum
    cleaner's HAL returns them) that also has the LaserData fields (`values`,
    `minAngle`, `maxAngle` rad with 0 to the robot's right and pi/2 ahead,
    `minRange`, `maxRange` m, `timeStamp` s), as the other exercises' HAL."""

    __slots__ = ("minAngle", "maxAngle", "minRange", "maxRange", "timeStamp")

    @property
    def values(self):
        return self

    def __str__(self):
        return (
            f"LaserData: {{ minAngle: {self.minAngle} maxAngle: {self.maxAngle} "
            f"minRange: {self.minRange} maxRange: {self.maxRange} "
            f"timeStamp: {self.timeStamp} values: {list.__repr__(self)} }}"
        )


def laser_values(values, min_angle, max_angle, min_range, max_range, stamp):
    l = LaserValues(values)
    l.minAngle, l.maxAngle = min_angle, max_angle
    l.minRange, l.maxRange, l.timeStamp = min_range, max_range, stamp
    return l


def add_program_dir(path):
    """The program's folder first on sys.path, as `python3 FILE` would put it."""
    import os

    d = os.path.dirname(os.path.abspath(path))
    if d not in sys.path:
        sys.path.insert(0, d)


def syntax_error(e, path):
    """`FILE:LINE: message` of a SyntaxError, and its line."""
    line = e.lineno or 0
    return f"{e.filename or path}:{line}: {e.msg}", line


def describe(e, tb, path):
    """(traceback text, the program's line where it happened or 0, one-line summary)."""
    if tb is None:
        tb = e.__traceback__
    text = "".join(traceback.format_exception(type(e), e, tb))
    line = 0
    for frame in traceback.extract_tb(tb):
        if frame.filename == path:
            line = frame.lineno or 0
    if isinstance(e, SyntaxError) and e.filename == path:
        line = e.lineno or 0
    message = str(e)
    what = type(e).__name__ + (f": {message}" if message else "")
    return text, line, f"{path}:{line}: {what}"


def add_venv(venv):
    """Adds a virtual environment's site-packages to sys.path; returns them."""
    import glob
    import site

    dirs = sorted(glob.glob(f"{venv}/lib/python3*/site-packages"))
    want = f"python{sys.version_info[0]}.{sys.version_info[1]}"
    dirs = [d for d in dirs if want in d] or dirs
    for d in dirs:
        if d not in sys.path:
            site.addsitedir(d)
    return dirs


def image_array(data, height, width, channels):
    """A writable numpy array over a bytearray (one copy, done by the caller)."""
    import numpy

    shape = (height, width, channels) if channels > 1 else (height, width)
    return numpy.frombuffer(data, dtype=numpy.uint8).reshape(shape)


def image_bytes(img):
    """(height, width, channels, bytes) of an image a program shows: a numpy
    array H x W (grey) or H x W x 3 (BGR); bool and float arrays are scaled."""
    import numpy

    a = numpy.asarray(img)
    if a.dtype == numpy.bool_:
        a = a.astype(numpy.uint8) * 255
    elif a.dtype != numpy.uint8:
        if not numpy.issubdtype(a.dtype, numpy.number):
            raise TypeError(f"GUI.showImage: an image is an array of numbers, not {a.dtype}")
        a = numpy.clip(a, 0, 255).astype(numpy.uint8)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim == 2:
        channels = 1
    elif a.ndim == 3 and a.shape[2] in (3, 4):
        a = a[:, :, :3]
        channels = 3
    else:
        raise ValueError(
            f"GUI.showImage: an image is H x W (grey) or H x W x 3 (BGR), not {a.shape}"
        )
    a = numpy.ascontiguousarray(a)
    return a.shape[0], a.shape[1], channels, a.tobytes()


class Pose:
    """A target's pose (`getPose()`): `x`, `y` in m, in the world's frame (the
    one `HAL.getPose3d()` gives on the simulator), `yaw` 0."""

    __slots__ = ("x", "y", "yaw")

    def __init__(self, x, y):
        self.x, self.y, self.yaw = x, y, 0.0

    def __repr__(self):
        return f"Pose: x={self.x:.3f} y={self.y:.3f}"


class Target:
    """A target of the obstacle-avoidance exercise, as `GUI.map.getNextTarget()`
    gives it: `getPose()`, `getId()`, `isReached()`, `setReached(True)`."""

    def __init__(self, id, x, y):
        self._id, self._pose, self._reached = id, Pose(x, y), False

    def getId(self):
        return self._id

    def getPose(self):
        return self._pose

    def isReached(self):
        return self._reached

    def setReached(self, value=True):
        self._reached = bool(value)

    def __repr__(self):
        return f"Target {self._id}: x={self._pose.x:.3f} y={self._pose.y:.3f} reached={self._reached}"


class Map:
    """`GUI.map` of the obstacle-avoidance exercise: the world's targets in
    order, and the attributes 4.x programs set for the GUI to draw
    (`targetx`/`targety`, `carx`/`cary`, `obsx`/`obsy`, `avgx`/`avgy`, in the
    robot's frame, m)."""

    def __init__(self):
        self.targets = []
        for a in ("targetx", "targety", "carx", "cary", "obsx", "obsy", "avgx", "avgy", "posx", "posy"):
            setattr(self, a, None)

    def getNextTarget(self):
        """The first target not yet reached (`setReached(True)` moves on); None
        after the last."""
        if not self.targets:
            raise RuntimeError(
                "GUI.map.getNextTarget: this world has no targets (the simulator's world file "
                "lists them as `target X Y` lines: assets/worlds/obstacle_circuit.world)"
            )
        for t in self.targets:
            if not t._reached:
                return t
        return None

    def getTargets(self):
        return list(self.targets)

    def reset(self):
        for t in self.targets:
            t._reached = False


MAP = Map()


def set_targets(points):
    """The world's targets, (x, y) in m, in order."""
    MAP.targets = [Target(i, x, y) for i, (x, y) in enumerate(points)]


def map_forces():
    """The forces a 4.x program set on GUI.map for the GUI to draw: (car,
    obstacle, average) as (x, y) pairs, or None if it set none."""
    pairs = [(MAP.carx, MAP.cary), (MAP.obsx, MAP.obsy), (MAP.avgx, MAP.avgy)]
    if all(x is None and y is None for x, y in pairs):
        return None
    return [(float(x or 0.0), float(y or 0.0)) for x, y in pairs]


def vec2(v, name):
    """Two floats from a list, tuple or numpy array (x, y)."""
    try:
        return float(v[0]), float(v[1])
    except (TypeError, IndexError, ValueError):
        raise TypeError(f"{name}: a vector is [x, y] (a list, tuple or array of two numbers), not {v!r}") from None


def install_rospy():
    """Where ROS 1 is not installed, a stand-in `rospy` with what the Academy's
    4.x programs pace themselves with: `rospy.sleep`, `rospy.Time.now()`
    (`.secs`, `.nsecs`, `.to_sec()`), `rospy.Duration`, `rospy.Rate(hz).sleep()`,
    `rospy.get_time()`, `rospy.is_shutdown()`, `rospy.loginfo`/`logwarn`/`logerr`,
    `rospy.init_node`. Anything else raises an AttributeError that says so."""
    import importlib.util
    import time
    import types

    if importlib.util.find_spec("rospy") is not None:
        return
    m = types.ModuleType("rospy", "jderobot's stand-in for ROS 1's rospy (time and logging only)")

    class Duration:
        def __init__(self, secs=0, nsecs=0):
            self._s = float(secs) + float(nsecs) * 1e-9

        def to_sec(self):
            return self._s

        @property
        def secs(self):
            return int(self._s)

        @property
        def nsecs(self):
            return int(round((self._s - int(self._s)) * 1e9))

        def __sub__(self, other):
            return Duration(self._s - other.to_sec())

        def __add__(self, other):
            return type(self)(self._s + other.to_sec())

        def __lt__(self, other):
            return self._s < other.to_sec()

        def __repr__(self):
            return f"rospy.{type(self).__name__}[{self._s:.9f}]"

    class Time(Duration):
        @staticmethod
        def now():
            return Time(time.time())

        def __sub__(self, other):
            return Duration(self._s - other.to_sec())

    class Rate:
        def __init__(self, hz):
            self._period, self._next = 1.0 / float(hz), None

        def sleep(self):
            now = time.monotonic()
            if self._next is None or now > self._next + self._period:
                self._next = now
            self._next += self._period
            time.sleep(max(0.0, self._next - now))

    def sleep(d):
        time.sleep(d.to_sec() if hasattr(d, "to_sec") else float(d))

    def log(*args, **kwargs):
        print(*args)

    def missing(name):
        raise AttributeError(
            f"rospy.{name} is not here: jderobot has no ROS 1; its stand-in rospy has sleep, "
            "Time, Duration, Rate, get_time, is_shutdown, loginfo, logwarn, logerr, init_node"
        )

    m.Duration, m.Time, m.Rate, m.sleep = Duration, Time, Rate, sleep
    m.get_time = time.time
    m.is_shutdown = lambda: False
    m.loginfo = m.logwarn = m.logerr = m.logdebug = log
    m.init_node = lambda *a, **k: None
    m.__getattr__ = missing
    sys.modules["rospy"] = m
