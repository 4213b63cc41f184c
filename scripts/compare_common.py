"""What scripts/compare_opencv.py and scripts/compare_photos.py share: the venv they
re-run in, timing a Python-side op, building the Rust example and writing the table."""

import json
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
VENV = os.path.join(ROOT, "target", "compare-venv")
# glibc hands every allocation above 128 KiB fresh mmapped pages (page faults on
# first touch) until its dynamic threshold adapts; a long-running process (Python
# here, a schema in jderobot) reuses its heap instead. The Rust process gets that
# steady state from the start.
TUNED_MALLOC = {"MALLOC_MMAP_THRESHOLD_": "67108864", "MALLOC_TRIM_THRESHOLD_": "134217728"}


def ensure_venv(packages):
    """Re-run the calling script inside the venv (creating it and installing
    `packages` when needed)."""
    py = os.path.join(VENV, "bin", "python")
    if os.path.abspath(sys.prefix) == os.path.abspath(VENV):
        return
    if not os.path.exists(py):
        subprocess.check_call([sys.executable, "-m", "venv", VENV])
    subprocess.check_call([py, "-m", "pip", "install", "-q"] + packages)
    os.execv(py, [py] + sys.argv)


def median(v):
    v = sorted(v)
    return v[len(v) // 2]


def median_ms(fn, repeats):
    """fn's median time in ms over `repeats` runs after a warm-up, and its last result."""
    out = fn()
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        ts.append((time.perf_counter() - t) * 1e3)
    return median(ts), out


def build_example(name, features=()):
    """Builds examples/NAME.rs (release); its executable as cargo reports it (the target
    dir may be shared, with other trees linking their own build to the same name)."""
    cmd = ["cargo", "build", "--release", "--no-default-features"]
    if features:
        cmd += ["--features", ",".join(features)]
    cmd += ["--example", name, "--message-format=json-render-diagnostics"]
    exe = None
    for line in subprocess.check_output(cmd, cwd=ROOT).decode().splitlines():
        msg = json.loads(line)
        if msg.get("reason") == "compiler-artifact" and msg["target"]["name"] == name:
            exe = msg.get("executable") or exe
    if exe is None:
        sys.exit(f"cargo did not report the {name} executable")
    return exe


def write_markdown(table, path):
    """The table into `path` too, when one is given."""
    if path:
        with open(path, "w") as f:
            f.write(table + "\n")
