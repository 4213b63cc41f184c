#!/usr/bin/env python3
"""Compare jderobot's vision/colour/fuzzy libraries with OpenCV and scikit-fuzzy.

Creates a venv under target/compare-venv (pip: opencv-python-headless, numpy,
scikit-fuzzy), writes a synthetic 640x480 scene and a shifted second frame, and the
same for every 640x480 photograph in assets/photos/ (real pictures: many edges and
textures), runs `examples/vision_compare.rs` (release build) on each input and the
same operations through OpenCV (cv2.setNumThreads(1)) / scikit-fuzzy, and prints
Markdown tables: per input and op the agreement (max abs difference) and the times,
then a summary of the photographs. The two sides run in alternating rounds (ROUNDS,
5 by default), each timing every op REPEATS times on every input; per input, op and
side the table keeps the fastest round's median, so load from other processes on a
shared machine does not decide a ratio.

    python3 scripts/compare_opencv.py [--repeats 50] [--rounds 5] [--markdown-out FILE]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

from compare_common import ROOT, TUNED_MALLOC, build_example, ensure_venv, median_ms, write_markdown

PHOTOS = os.path.join(ROOT, "assets", "photos")
W, H = 640, 480
# Ops whose input does not depend on the image: tabled for the synthetic scene only.
IMAGE_FREE = {"calibrate", "find_homography", "fuzzy_jde", "fuzzy_mamdani"}


def scene(np, cv2):
    """A textured scene: gradients, shapes, text and noise (deterministic)."""
    rng = np.random.default_rng(43)
    y, x = np.mgrid[0:H, 0:W].astype(np.float32)
    img = np.zeros((H, W, 3), np.float32)
    img[..., 0] = 128 + 100 * np.sin(x / 37.0) * np.cos(y / 53.0)
    img[..., 1] = 255 * x / W
    img[..., 2] = 255 * y / H
    img = img.astype(np.uint8)
    for _ in range(60):
        c = tuple(int(v) for v in rng.integers(0, 256, 3))
        p = (int(rng.integers(0, W)), int(rng.integers(0, H)))
        if rng.random() < 0.5:
            cv2.circle(img, p, int(rng.integers(5, 60)), c, -1)
        else:
            q = (p[0] + int(rng.integers(-80, 80)), p[1] + int(rng.integers(-80, 80)))
            cv2.rectangle(img, p, q, c, -1)
    cv2.putText(img, "JDE 4.3", (120, 260), cv2.FONT_HERSHEY_SIMPLEX, 3, (20, 220, 240), 6)
    noise = rng.normal(0, 6, img.shape)
    return np.clip(img.astype(np.float64) + noise, 0, 255).astype(np.uint8)


def load_kernel(path, np):
    size, modulo, offset, rows = 3, 1, 0, {}
    for line in open(path):
        line = line.split("#")[0].split()
        if not line:
            continue
        if line[0] == "size":
            size = int(line[1])
        elif line[0] == "modulo":
            modulo = int(line[1])
        elif line[0] == "offset":
            offset = int(line[1])
        elif line[0] == "row":
            rows[int(line[1])] = [float(v) for v in line[2:]]
    k = np.array([rows[i + 1] for i in range(size)], np.float32)
    if modulo > 1:
        k = k / np.float32(modulo)
    return k, offset


def fuzzy_jde_reference(v1, v2, labels, rules):
    """4.3.0's fuzzylib inference (product AND, per-rule clipped centroid, weighted mean)."""

    def mu(t, x):
        p0, p1, p2, p3 = t
        if p0 < x < p1:
            return (x - p0) / (p1 - p0)
        if p2 < x < p3:
            return (p3 - x) / (p3 - p2)
        if p1 <= x <= p2:
            return 1.0
        return 0.0

    def centroid(t, a):
        p0, p1, p2, p3 = t
        m1, c1 = (p1 - p0) * a * a / 2, p0 + 2 * (p1 - p0) * a / 3
        wd = (p3 - p0) - a * (p3 - p2) - a * (p1 - p0)
        m2, c2 = a * wd, p0 + a * (p1 - p0) + wd / 2
        m3, c3 = (p3 - p2) * a * a / 2, p3 - 2 * a * (p3 - p2) / 3
        m = m1 + m2 + m3
        return (m1 * c1 + m2 * c2 + m3 * c3) / m if m > 0 else (p0 + p3) / 2

    vals = {"fuzzyvar1": v1, "fuzzyvar2": v2}
    num = den = 0.0
    n = 0
    for ante, cons in rules:
        a = 1.0
        for var, lab in ante:
            a *= mu(labels[(var, lab)], vals[var])
        if a > 0:
            num += a * centroid(labels[("fuzzyvar3", cons)], a)
            den += a
            n += 1
    return (num / den, n) if n else (float("nan"), 0)


def main():
    ensure_venv(["opencv-python-headless", "numpy", "scikit-fuzzy", "scipy", "networkx", "packaging"])
    import cv2
    import numpy as np
    import skfuzzy as fuzz
    from skfuzzy import control as ctrl

    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=50)
    ap.add_argument("--rounds", type=int, default=5,
                    help="alternate the Rust and OpenCV sides this many times")
    ap.add_argument("--markdown-out")
    ap.add_argument("--untuned-malloc", action="store_true",
                    help="run the Rust side with glibc's default mmap threshold")
    args = ap.parse_args()
    R = args.repeats
    cv2.setNumThreads(1)

    def setup(a):
        """Writes the inputs for BGR frame `a` (640x480) into a new directory."""
        d = tempfile.mkdtemp(prefix="jderobot-compare-")
        # Second frame: the scene moved by a sub-pixel shift and slightly re-noised.
        m = np.float32([[1, 0, 2.3], [0, 1, -1.7]])
        b = cv2.warpAffine(a, m, (W, H), borderMode=cv2.BORDER_REFLECT_101)
        a.tofile(os.path.join(d, "a.bgr"))
        b.tofile(os.path.join(d, "b.bgr"))
        g = cv2.cvtColor(a, cv2.COLOR_BGR2GRAY)
        gb = cv2.cvtColor(b, cv2.COLOR_BGR2GRAY)
        cv2.Canny(g, 50, 150).tofile(os.path.join(d, "edges.raw"))
        # calibrador: a box corner (3 planes, 7x7 points 60 mm apart) seen by a known
        # 640x480 camera, pixels with 0.5 px Gaussian noise.
        obj = []
        for i in range(1, 8):
            for j in range(1, 8):
                a_, b_ = i * 60.0, j * 60.0
                obj += [[0, a_, b_], [a_, 0, b_], [a_, b_, 0]]
        obj = np.float64(obj)
        cam_c = np.float64([1400, 1100, 900])
        fwd = np.float64([150, 150, 150]) - cam_c
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, [0, 0, 1.0])
        right /= np.linalg.norm(right)
        rot = np.array([right, np.cross(fwd, right), fwd])
        k_true = np.float64([[600, 0, 330], [0, 620, 229], [0, 0, 1]])
        cc = (rot @ (obj - cam_c).T).T
        pix = (k_true @ (cc / cc[:, 2:3]).T).T[:, :2] + np.random.default_rng(5).normal(0, 0.5, (len(obj), 2))
        np.savetxt(os.path.join(d, "calib.txt"), np.hstack([obj, pix]), fmt="%.10g")
        pts = cv2.goodFeaturesToTrack(g, 200, 0.01, 10).reshape(-1, 2)
        np.savetxt(os.path.join(d, "points.txt"), pts, fmt="%.6f")
        # Homography: imgrectifier's 4 clicked corners -> a rectangle, plus 4 more exact pairs.
        src = np.float64([[100, 80], [560, 40], [600, 450], [60, 400]])
        dst = np.float64([[0, 0], [639, 0], [639, 479], [0, 479]])
        htrue = cv2.getPerspectiveTransform(src.astype(np.float32), dst.astype(np.float32))
        extra = np.float64([[300, 200], [200, 300], [450, 120], [500, 350]])
        ex = cv2.perspectiveTransform(extra.reshape(-1, 1, 2), htrue).reshape(-1, 2)
        src8, dst8 = np.vstack([src, extra]), np.vstack([dst, ex])
        np.savetxt(os.path.join(d, "homography.txt"), np.hstack([src8, dst8]), fmt="%.17g")
        hsv = [200.5, 265.3, 0.2137, 0.9, 40.5, 250.5]  # H degrees, S 0..1, V 0..255
        np.savetxt(os.path.join(d, "hsv.txt"), [hsv], fmt="%.6f")
        rng = np.random.default_rng(7)
        fin = np.column_stack([rng.uniform(7000, 20000, 40), rng.uniform(150, 800, 40)])
        fin = np.vstack([[12000, 500], fin])
        np.savetxt(os.path.join(d, "fuzzy.txt"), fin, fmt="%.3f")
        # Camera frames: YUYV 4:2:2 (BT.601 video range) and an RGGB Bayer mosaic of the scene.
        yuv = cv2.cvtColor(a, cv2.COLOR_BGR2YUV)
        yuyv = np.empty((H, W, 2), np.uint8)
        yuyv[:, :, 0] = (yuv[:, :, 0].astype(np.int32) * 219 // 255 + 16).astype(np.uint8)
        yuyv[:, 0::2, 1] = yuv[:, 0::2, 1]
        yuyv[:, 1::2, 1] = yuv[:, 0::2, 2]
        yuyv.tofile(os.path.join(d, "a.yuyv"))
        bayer = np.empty((H, W), np.uint8)
        bayer[0::2, 0::2] = a[0::2, 0::2, 2]
        bayer[0::2, 1::2] = a[0::2, 1::2, 1]
        bayer[1::2, 0::2] = a[1::2, 0::2, 1]
        bayer[1::2, 1::2] = a[1::2, 1::2, 0]
        bayer.tofile(os.path.join(d, "a.bayer"))
        return dict(d=d, a=a, b=b, g=g, gb=gb, pts=pts, fin=fin, hsv=hsv, yuyv=yuyv,
                    bayer=bayer, src8=src8, dst8=dst8)

    photos = sorted(f for f in os.listdir(PHOTOS) if f.endswith((".jpg", ".png")))
    inputs = [("synthetic scene", setup(scene(np, cv2)))]
    for f in photos:
        img = cv2.imread(os.path.join(PHOTOS, f))
        if img is None or img.shape != (H, W, 3):
            sys.exit(f"{PHOTOS}/{f}: not a {W}x{H} colour image")
        inputs.append((os.path.splitext(f)[0], setup(img)))

    # The example needs only the calibrador feature (its solver); the library's
    # vision code has none.
    exe = build_example("vision_compare", ["calibrador"])
    # The Rust process in a long-running process's steady state (compare_common's
    # TUNED_MALLOC); --untuned-malloc measures without it.
    env = dict(os.environ)
    if not args.untuned_malloc:
        env.update(TUNED_MALLOC)
    def measure(ctx):
        """One round: the Rust side's times and outputs, then OpenCV's; the rows."""
        d, a, b, g, gb, pts, fin, hsv, yuyv, bayer, src8, dst8 = (ctx[k] for k in (
            "d", "a", "b", "g", "gb", "pts", "fin", "hsv", "yuyv", "bayer", "src8", "dst8"))
        rs = json.loads(
            subprocess.check_output([exe, d, str(W), str(H), str(R)], cwd=ROOT, env=env).decode()
        )

        def raw(name, dtype, shape):
            return np.fromfile(os.path.join(d, name), dtype).reshape(shape)

        rows = []  # (op, agreement, rust ms, opencv ms, note)

        def add(op, rs_key, diff, cv_ms, note=""):
            rows.append((op, diff, rs[rs_key], cv_ms, note, rs_key))

        t, cg = median_ms(lambda: cv2.cvtColor(a, cv2.COLOR_BGR2GRAY), R)
        diff = int(np.abs(cg.astype(int) - raw("rs_gray.raw", np.uint8, (H, W))).max())
        add("grayscale (BGR2GRAY)", "gray", str(diff), t)

        lo = np.array([hsv[0], hsv[2], hsv[4]], np.float32)
        hi = np.array([hsv[1], hsv[3], hsv[5]], np.float32)
        t, cm = median_ms(
            lambda: cv2.inRange(cv2.cvtColor(a.astype(np.float32), cv2.COLOR_BGR2HSV), lo, hi), R
        )
        rm = raw("rs_hsv.raw", np.uint8, (H, W))
        nd = int((cm != rm).sum())
        add("HSV colour filter (float HSV + inRange)", "hsv_filter",
            f"{int(np.abs(cm.astype(int) - rm).max())} ({nd} px differ)", t,
            f"{int((rm > 0).sum())} px pass")

        def sob():
            return (cv2.Sobel(g, cv2.CV_16S, 1, 0, ksize=3), cv2.Sobel(g, cv2.CV_16S, 0, 1, ksize=3))

        t, (cx, cy) = median_ms(sob, R)
        dxd = np.abs(cx.astype(int) - raw("rs_sobel_dx.raw", "<i2", (H, W))).max()
        dyd = np.abs(cy.astype(int) - raw("rs_sobel_dy.raw", "<i2", (H, W))).max()
        add("Sobel 3x3 dx + dy (CV_16S)", "sobel_dx_dy", str(int(max(dxd, dyd))), t)

        t, ce = median_ms(lambda: cv2.Canny(g, 50, 150), R)
        re_ = raw("rs_canny.raw", np.uint8, (H, W))
        nd = int((ce != re_).sum())
        add("Canny 50/150 (L1)", "canny", f"{int(np.abs(ce.astype(int) - re_).max())} ({nd} px differ)", t,
            f"{int((ce > 0).sum())} edge px")

        # Hough on the same edges (OpenCV's Canny): lines (rho, theta) in order, and segments.
        edges = raw("edges.raw", np.uint8, (H, W))
        t, cl = median_ms(lambda: cv2.HoughLines(edges, 1, np.pi / 180, 80), R)
        cl = np.zeros((0, 2)) if cl is None else cl.reshape(-1, 2)
        rl = np.loadtxt(os.path.join(d, "rs_hough.txt"), ndmin=2).reshape(-1, 2)
        n = min(len(cl), len(rl))
        diff = float(np.abs(cl[:n] - rl[:n]).max()) if n else 0.0
        add("HoughLines (1 px, 1°, 80 votes)", "hough_lines",
            f"{diff:.1e} ({len(cl)} vs {len(rl)} lines)", t, f"{int((edges > 0).sum())} edge px")
        t, cs = median_ms(lambda: cv2.HoughLinesP(edges, 1, np.pi / 180, 50, minLineLength=30, maxLineGap=5), R)
        cs = np.zeros((0, 4), int) if cs is None else cs.reshape(-1, 4)
        rsg = np.loadtxt(os.path.join(d, "rs_houghp.txt"), ndmin=2).reshape(-1, 4).astype(int)
        same = sum(1 for p, q in zip(cs, rsg) if (p == q).all())
        add("HoughLinesP (1 px, 1°, 50 votes, length 30, gap 5)", "hough_lines_p",
            f"{same}/{len(cs)} segments identical ({len(rsg)} ours)", t)

        # calibrador: reprojection error against OpenCV's calibrateCamera (pinhole
        # only: no distortion, started from a rough guess) and solvePnP with its K.
        cal = np.loadtxt(os.path.join(d, "calib.txt"))
        o3, p2 = cal[:, :3].astype(np.float32), cal[:, 3:].astype(np.float32)
        flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K1
                 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3)
        k0 = np.float64([[500, 0, 320], [0, 500, 240], [0, 0, 1]])

        def cvcal():
            return cv2.calibrateCamera([o3], [p2], (W, H), k0.copy(), None, flags=flags)

        t, (cv_rms, kc, dc, rv, tv) = median_ms(cvcal, max(3, R // 5))
        ok, rv2, tv2 = cv2.solvePnP(o3, p2, kc, dc)
        proj, _ = cv2.projectPoints(o3, rv2, tv2, kc, dc)
        pnp_rms = float(np.sqrt(((proj.reshape(-1, 2) - p2) ** 2).sum(1).mean()))
        rc = np.loadtxt(os.path.join(d, "rs_calib.txt"))
        add("calibrador (147 pts, 3 planes, 0.5 px noise) vs calibrateCamera", "calibrate",
            f"rms {rc[0]:.4f} vs {cv_rms:.4f} px (solvePnP {pnp_rms:.4f})", t,
            f"fx {rc[1]:.2f}/{kc[0, 0]:.2f} fy {rc[2]:.2f}/{kc[1, 1]:.2f} (true 600/620)")

        t, cp = median_ms(lambda: cv2.pyrDown(a), R)
        diff = int(np.abs(cp.astype(int) - raw("rs_pyrdown.raw", np.uint8, cp.shape)).max())
        add("pyrDown (BGR)", "pyrdown", str(diff), t)

        for name in ["sharpen", "gaussian5", "edge"]:
            k, off = load_kernel(os.path.join(ROOT, "assets", "kernels", name + ".kernel"), np)
            t, cc = median_ms(
                lambda: cv2.filter2D(a, -1, k, delta=off, borderType=cv2.BORDER_REFLECT_101), R
            )
            rc = raw(f"rs_conv_{name}.raw", np.uint8, (H, W, 3))
            diff = int(np.abs(cc.astype(int) - rc).max())
            add(f"filter2D {name} {k.shape[0]}x{k.shape[0]} (BGR)", f"filter2d_{name}",
                f"{diff} ({int((cc != rc).sum())} values differ)", t)

        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01)
        p0 = pts.reshape(-1, 1, 2).astype(np.float32)

        def lk():
            return cv2.calcOpticalFlowPyrLK(g, gb, p0, None, winSize=(21, 21), maxLevel=3, criteria=crit)

        t, (cp1, cst, _) = median_ms(lk, R)
        rl = np.loadtxt(os.path.join(d, "rs_lk.txt"))
        both = (cst.reshape(-1) == 1) & (rl[:, 2] == 1)
        diff = np.abs(cp1.reshape(-1, 2)[both] - rl[both, :2]).max()
        stat = int((cst.reshape(-1) != rl[:, 2]).sum())
        truth = np.abs(rl[both, :2] - (pts[both] + [2.3, -1.7])).max()
        add(f"optical flow LK ({len(pts)} points, 21x21, 3 levels)", "optical_flow_lk",
            f"{diff:.4f} px ({stat} status differ)", t, f"max error vs true shift {truth:.3f} px")

        t, (ch, _) = median_ms(lambda: cv2.findHomography(src8, dst8, 0), R)
        rh = np.loadtxt(os.path.join(d, "rs_homography.txt")).reshape(3, 3)
        add("findHomography (8 pairs, least squares)", "find_homography",
            f"{np.abs(ch / ch[2, 2] - rh).max():.2e}", t)

        t, cw = median_ms(lambda: cv2.warpPerspective(a, rh, (W, H)), R)
        rw = raw("rs_warp.raw", np.uint8, (H, W, 3))
        add("warpPerspective (bilinear, BGR)", "warp_perspective",
            f"{int(np.abs(cw.astype(int) - rw).max())} ({int((cw != rw).sum())} values differ)", t)

        # Camera conversions (the drivers' pixfmt), into a preallocated output as the
        # drivers do. OpenCV names Bayer codes by the second row: an RGGB mosaic is BayerBG.
        out = np.empty((H, W, 3), np.uint8)
        t, cy = median_ms(lambda: cv2.cvtColor(yuyv, cv2.COLOR_YUV2BGR_YUYV, dst=out), R)
        ry = raw("rs_yuyv.raw", np.uint8, (H, W, 3))
        add("YUYV -> BGR (BT.601)", "yuyv_bgr",
            f"{int(np.abs(cy.astype(int) - ry).max())} ({int((cy != ry).sum())} values differ)", t)
        t, cb = median_ms(lambda: cv2.cvtColor(bayer, cv2.COLOR_BayerBG2BGR, dst=out), R)
        rb = raw("rs_bayer.raw", np.uint8, (H, W, 3))
        inner = np.abs(cb[1:-1, 1:-1].astype(int) - rb[1:-1, 1:-1]).max()
        add("Bayer RGGB -> BGR (bilinear)", "bayer_bgr", f"{int(inner)} inside the 1-px border", t,
            "libdc1394's border is black, OpenCV's replicated")

        # Fuzzy: 4.3's inference against a Python transcription; Mamdani against scikit-fuzzy.
        labels = {
            ("fuzzyvar1", "valuename1"): (8000, 12000, 16000, 20000),
            ("fuzzyvar1", "valuename2"): (1000, 2000, 4000, 8000),
            ("fuzzyvar1", "valuename3"): (300, 500, 800, 1000),
            ("fuzzyvar2", "valuename4"): (300, 500, 600, 800),
            ("fuzzyvar2", "valuename5"): (200, 225, 275, 300),
            ("fuzzyvar2", "valuename6"): (100, 175, 187, 200),
            ("fuzzyvar3", "valuename7"): (-40, -35, -30, -25),
            ("fuzzyvar3", "valuename8"): (-25, -20, -15, -10),
            ("fuzzyvar3", "valuename9"): (0, 0, 0, 0),
        }
        rules = [
            ([("fuzzyvar1", "valuename1"), ("fuzzyvar2", "valuename4")], "valuename7"),
            ([("fuzzyvar1", "valuename3"), ("fuzzyvar2", "valuename6")], "valuename7"),
            ([("fuzzyvar2", "valuename5"), ("fuzzyvar1", "valuename1")], "valuename9"),
            ([("fuzzyvar1", "valuename1")], "valuename8"),
            ([("fuzzyvar2", "valuename6")], "valuename9"),
        ]
        rj = np.loadtxt(os.path.join(d, "rs_fuzzy_jde.txt"))
        t, ref = median_ms(lambda: [fuzzy_jde_reference(v1, v2, labels, rules) for v1, v2 in fin], R)
        ok = [i for i, r in enumerate(ref) if r[1] > 0]
        diff = max(abs(rj[i, 0] - ref[i][0]) for i in ok)
        nd = sum(int(rj[i, 1]) != ref[i][1] for i in ok)
        add(f"fuzzy 4.3 inference ({len(fin)} inputs; example = {rj[0, 0]:g}, {int(rj[0, 1])} rules)",
            "fuzzy_jde", f"{diff:.1e} ({nd} rule counts differ)", t, "vs Python transcription of 4.3")

        u1 = np.arange(0, 20001, 1.0)
        u2 = np.arange(0, 1001, 1.0)
        u3 = np.round(np.arange(-45, 5.0001, 0.01), 2)
        v1, v2 = ctrl.Antecedent(u1, "fuzzyvar1"), ctrl.Antecedent(u2, "fuzzyvar2")
        v3 = ctrl.Consequent(u3, "fuzzyvar3")
        for (var, lab), p in labels.items():
            obj = {"fuzzyvar1": v1, "fuzzyvar2": v2, "fuzzyvar3": v3}[var]
            obj[lab] = fuzz.trapmf(obj.universe, list(p))
        sk_rules = []
        for ante, cons in rules:
            term = None
            for var, lab in ante:
                t_ = {"fuzzyvar1": v1, "fuzzyvar2": v2}[var][lab]
                term = t_ if term is None else term & t_
            sk_rules.append(ctrl.Rule(term, v3[cons]))
        sim = ctrl.ControlSystemSimulation(ctrl.ControlSystem(sk_rules))

        def skrun():
            out = []
            for x1, x2 in fin:
                sim.input["fuzzyvar1"] = x1
                sim.input["fuzzyvar2"] = x2
                try:
                    sim.compute()
                    out.append(sim.output["fuzzyvar3"])
                except Exception:  # only singletons fired: no area
                    out.append(float("nan"))
            return out

        t, sk = median_ms(skrun, max(3, R // 10))
        rmd = np.loadtxt(os.path.join(d, "rs_fuzzy_mamdani.txt"))
        ok = [i for i, v in enumerate(sk) if np.isfinite(v) and np.isfinite(rmd[i, 0])]
        # The singleton valuename9 (0 0 0 0) has no area; on scikit-fuzzy's sampled universe
        # it is a triangle one step wide, so inputs that fire it (fuzzyvar2 < 300) differ
        # by that discretisation. Report the two groups apart.
        plain = [i for i in ok if fin[i][1] >= 300]
        single = [i for i in ok if fin[i][1] < 300]
        diff = max(abs(rmd[i, 0] - sk[i]) for i in plain)
        sdiff = max((abs(rmd[i, 0] - sk[i]) for i in single), default=0.0)
        add(f"fuzzy Mamdani ({len(plain)} inputs; {len(single)} more fire the singleton)", "fuzzy_mamdani",
            f"{diff:.1e}", t,
            f"vs scikit-fuzzy (universe step 0.01); with the singleton firing: {sdiff:.1e}")
        return rows

    # The machine is shared: alternate the two sides over ROUNDS rounds (each round
    # runs every input) and keep, per input, op and side, the fastest round's median
    # (the least disturbed). Outputs are the same every round.
    rounds = [[measure(ctx) for _, ctx in inputs] for _ in range(args.rounds)]
    tables = []
    per_input = []
    for n, (name, ctx) in enumerate(inputs):
        rows = []
        for k, (op, diff, _, _, note, key) in enumerate(rounds[-1][n]):
            if n > 0 and key in IMAGE_FREE:
                continue
            rows.append((op, diff, min(r[n][k][2] for r in rounds), min(r[n][k][3] for r in rounds), note))
        per_input.append(rows)
        lines = [
            f"| op ({name}, 640x480, 1 thread) | max abs diff | jderobot ms | reference ms | ratio | note |",
            "|---|---|---|---|---|---|",
        ]
        for op, diff, r_ms, c_ms, note in rows:
            lines.append(f"| {op} | {diff} | {r_ms:.3f} | {c_ms:.3f} | {r_ms / c_ms:.2f}x | {note} |")
        tables.append("\n".join(lines))
    # Summary of the photographs: per image op, ours / OpenCV's ms and the ratio (the
    # agreement is in each photograph's own table).
    names = [name for name, _ in inputs[1:]]
    lines = ["| op (photographs, 640x480; jderobot / OpenCV ms) | " + " | ".join(names) + " | worst ratio |",
             "|---|" + "---|" * (len(names) + 1)]
    for k, row in enumerate(per_input[0] if len(per_input) == 1 else per_input[1]):
        cells, worst = [], 0.0
        for rows in per_input[1:]:
            _, diff, r_ms, c_ms, _ = rows[k]
            worst = max(worst, r_ms / c_ms)
            cells.append(f"{r_ms:.3f} / {c_ms:.3f} ({r_ms / c_ms:.2f}x)")
        lines.append(f"| {row[0]} | " + " | ".join(cells) + f" | {worst:.2f}x |")
    if names:
        tables.append("\n".join(lines))
    table = "\n\n".join(tables)
    print(f"OpenCV {cv2.__version__}, numpy {np.__version__}, scikit-fuzzy {fuzz.__version__}; "
          f"per side the fastest of {args.rounds} alternating rounds' medians of {R} runs; "
          f"photos from {PHOTOS}; inputs in {', '.join(ctx['d'] for _, ctx in inputs)}")
    print(table)
    write_markdown(table, args.markdown_out)

if __name__ == "__main__":
    main()
