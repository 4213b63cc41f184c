#!/usr/bin/env python3
"""HoughLinesP and pyramidal LK flow, jderobot against OpenCV, on many photographs.

The photographs are every photograph (colour or grey) that scikit-image's wheel ships
in `skimage/data/` (no download), each at 640x480 (cropped to 4:3 around the centre
and resized as assets/photos/ was made) and at its own size. Sets: "tuned" (the four
in assets/photos/, which the code was tuned on), "unseen 640x480" and "unseen own
size" (all the others). Per photo: OpenCV's Canny 50/150 edges feed both
HoughLinesP (1 px, 1 deg, 50 votes, length 30, gap 5), and LK (200 points from
goodFeaturesToTrack, 21x21, 3 levels, 30 iterations / 0.01) tracks them into a frame
shifted by (2.3, -1.7) px. The Rust side is `examples/vision_photos.rs` (release);
OpenCV runs here with cv2.setNumThreads(1). Each round times every photo on both
sides (REPEATS runs, median), the sides alternating; a figure is the median of the
ROUNDS rounds' medians. Agreement: segments identical to OpenCV's, in order; LK's
largest position difference where both found the point, and status differences.

    python3 scripts/compare_photos.py [--repeats 21] [--rounds 5] [--markdown-out FILE]
"""

import argparse
import json
import os
import shutil
import subprocess
import tempfile

from compare_common import (ROOT, TUNED_MALLOC, build_example, ensure_venv, median, median_ms,
                            write_markdown)

RUST_ENV = dict(os.environ, **TUNED_MALLOC)
TUNED = ["astronaut", "chelsea", "coffee", "gravel"]
# Drawings, synthetic test patterns and binary masks are not photographs.
NOT_PHOTOS = {"chessboard_GRAY", "chessboard_RGB", "color", "horse", "logo", "phantom",
              "lbpcascade_frontalface_opencv", "no_time_for_that_tiny"}


def photographs(np, cv2):
    """(name, BGR image) for every photograph in skimage/data, at its own size."""
    import skimage
    d = os.path.join(os.path.dirname(skimage.__file__), "data")
    out = []
    for f in sorted(os.listdir(d)):
        name, ext = os.path.splitext(f)
        if ext not in (".png", ".jpg") or name in NOT_PHOTOS:
            continue
        img = cv2.imread(os.path.join(d, f), cv2.IMREAD_COLOR)
        if img is None or min(img.shape[:2]) < 64:
            continue
        out.append((name, img))
    return out


def to_640(img, cv2):
    """Crop to 4:3 around the centre and resize to 640x480 (as assets/photos/)."""
    h, w = img.shape[:2]
    if w * 3 > h * 4:
        cw, ch = h * 4 // 3, h
    else:
        cw, ch = w, w * 3 // 4
    x0, y0 = (w - cw) // 2, (h - ch) // 2
    crop = img[y0:y0 + ch, x0:x0 + cw]
    interp = cv2.INTER_AREA if cw > 640 else cv2.INTER_CUBIC
    return cv2.resize(crop, (640, 480), interpolation=interp)


def setup(img, np, cv2):
    """Writes one photo's inputs into a new directory; returns what OpenCV needs."""
    d = tempfile.mkdtemp(prefix="jderobot-photos-")
    h, w = img.shape[:2]
    m = np.float32([[1, 0, 2.3], [0, 1, -1.7]])
    b = cv2.warpAffine(img, m, (w, h), borderMode=cv2.BORDER_REFLECT_101)
    g, gb = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), cv2.cvtColor(b, cv2.COLOR_BGR2GRAY)
    edges = cv2.Canny(g, 50, 150)
    g.tofile(os.path.join(d, "a.gray"))
    gb.tofile(os.path.join(d, "b.gray"))
    edges.tofile(os.path.join(d, "edges.raw"))
    pts = cv2.goodFeaturesToTrack(g, 200, 0.01, 10).reshape(-1, 2)
    np.savetxt(os.path.join(d, "points.txt"), pts, fmt="%.6f")
    return dict(d=d, w=w, h=h, g=g, gb=gb, edges=edges, pts=pts)


def measure(exe, ctx, repeats, np, cv2):
    """One round on one photo: the Rust side, then OpenCV; (times, agreement)."""
    d = ctx["d"]
    rs = json.loads(subprocess.check_output(
        [exe, d, str(ctx["w"]), str(ctx["h"]), str(repeats)], cwd=ROOT, env=RUST_ENV).decode())
    edges, g, gb, pts = ctx["edges"], ctx["g"], ctx["gb"], ctx["pts"]
    t_h, cs = median_ms(lambda: cv2.HoughLinesP(edges, 1, np.pi / 180, 50, minLineLength=30,
                                                maxLineGap=5), repeats)
    cs = np.zeros((0, 4), int) if cs is None else cs.reshape(-1, 4)
    rsg = np.loadtxt(os.path.join(d, "rs_houghp.txt"), ndmin=2).reshape(-1, 4).astype(int)
    same = len(cs) == len(rsg) and bool((cs == rsg).all())
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01)
    p0 = pts.reshape(-1, 1, 2).astype(np.float32)
    t_l, (cp1, cst, _) = median_ms(lambda: cv2.calcOpticalFlowPyrLK(
        g, gb, p0, None, winSize=(21, 21), maxLevel=3, criteria=crit), repeats)
    rl = np.loadtxt(os.path.join(d, "rs_lk.txt"), ndmin=2)
    both = (cst.reshape(-1) == 1) & (rl[:, 2] == 1)
    lk_diff = float(np.abs(cp1.reshape(-1, 2)[both] - rl[both, :2]).max()) if both.any() else 0.0
    status = int((cst.reshape(-1) != rl[:, 2]).sum())
    return dict(hough=(rs["hough_lines_p"], t_h), lk=(rs["optical_flow_lk"], t_l),
                segs=(len(rsg), len(cs), same), lk_diff=lk_diff, status=status,
                npts=len(pts), edge_px=int((edges > 0).sum()))


def table(title, names, inputs, results):
    """A Markdown table of one photo set: per photo ours / OpenCV ms and agreement."""
    lines = [f"| {title} | size | edge px | HoughLinesP ms (ours / OpenCV) | ratio | segments "
             "(ours / OpenCV, same?) | LK ms (ours / OpenCV) | ratio | LK max diff px (status differ) |",
             "|---|---|---|---|---|---|---|---|---|"]
    worst_h = worst_l = 0.0
    for n in names:
        ctx, rounds = inputs[n], results[n]
        rh, ch = (median([r["hough"][k] for r in rounds]) for k in (0, 1))
        rl, cl = (median([r["lk"][k] for r in rounds]) for k in (0, 1))
        last = rounds[-1]
        ours, cvs, same = last["segs"]
        worst_h, worst_l = max(worst_h, rh / ch), max(worst_l, rl / cl)
        lines.append(
            f"| {n} | {ctx['w']}x{ctx['h']} | {last['edge_px']} | {rh:.3f} / {ch:.3f} | {rh / ch:.2f}x "
            f"| {ours} / {cvs} {'identical' if same else 'DIFFER'} | {rl:.3f} / {cl:.3f} | {rl / cl:.2f}x "
            f"| {last['lk_diff']:.4f} ({last['status']}) |")
    lines.append(f"| **worst** | | | | **{worst_h:.2f}x** | | | **{worst_l:.2f}x** | |")
    return "\n".join(lines)


def main():
    ensure_venv(["opencv-python-headless", "numpy", "scikit-image"])
    import cv2
    import numpy as np

    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=21)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--only", help="comma-separated photo names (all by default)")
    ap.add_argument("--markdown-out")
    ap.add_argument("--exe", help="a vision_photos executable built before (skips cargo)")
    args = ap.parse_args()
    cv2.setNumThreads(1)
    exe = args.exe or build_example("vision_photos")


    only = set(args.only.split(",")) if args.only else None
    inputs, sets = {}, {"tuned (640x480)": [], "unseen (640x480)": [], "unseen (own size)": []}
    for name, img in photographs(np, cv2):
        if only and name not in only:
            continue
        key = f"{name} 640"
        inputs[key] = setup(to_640(img, cv2), np, cv2)
        sets["tuned (640x480)" if name in TUNED else "unseen (640x480)"].append(key)
        if name not in TUNED and img.shape[:2] != (480, 640):
            inputs[name] = setup(img, np, cv2)
            sets["unseen (own size)"].append(name)
    results = {n: [] for n in inputs}
    for _ in range(args.rounds):
        for n, ctx in inputs.items():
            results[n].append(measure(exe, ctx, args.repeats, np, cv2))
    for ctx in inputs.values():
        shutil.rmtree(ctx["d"])
    out = "\n\n".join(table(title, names, inputs, results) for title, names in sets.items() if names)
    print(f"OpenCV {cv2.__version__}, numpy {np.__version__}; medians of {args.rounds} alternating "
          f"rounds' medians of {args.repeats} runs, one thread")
    print(out)
    write_markdown(out, args.markdown_out)


if __name__ == "__main__":
    main()
