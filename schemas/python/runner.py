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
