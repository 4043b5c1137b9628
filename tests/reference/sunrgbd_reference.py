#!/usr/bin/env python3
"""Independent reference numbers for tests/frame_real.rs, computed with numpy + Pillow, not with the crate.

Usage: python3 tests/reference/sunrgbd_reference.py ../shared/data/sunrgbd/kv1-b3dodata-img_0063

It follows the SUN RGB-D toolbox (read3dPoints.m) literally: depth PNG rotated right by 3 bits, /1000,
clamped at 8 m; 1-based pixel grid; Rtilt = P E P^T; points = Rtilt (x, z, -y). Box membership is tested
directly on the annotation polygon (point-in-convex-quadrilateral by edge signs, then Ymin/Ymax), not by
converting to centre/size/yaw as the crate does, so the two are independent; it also re-derives the
crate's documented rectangle convention (width axis p1->p2, centre = corner mean) with numpy, since the
annotation quadrilaterals are not always exact rectangles.
"""
import glob, json, os, sys
import numpy as np
from PIL import Image

d = sys.argv[1]
depth_file = glob.glob(os.path.join(d, "depth", "*.png"))[0]
raw = np.array(Image.open(depth_file)).astype(np.uint32)
mm = ((raw >> 3) | (raw << 13)) & 0xFFFF
z = np.minimum(mm / 1000.0, 8.0)
h, w = z.shape
K = np.loadtxt(os.path.join(d, "intrinsics.txt"))
E = np.loadtxt(sorted(glob.glob(os.path.join(d, "extrinsics", "*.txt")))[-1])[:, :3]
P = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], float)
Rtilt = P @ E @ P.T
u, v = np.meshgrid(np.arange(1, w + 1), np.arange(1, h + 1))
valid = mm > 0
x3 = (u - K[0, 2]) * z / K[0, 0]
y3 = (v - K[1, 2]) * z / K[1, 1]
cam = np.stack([x3[valid], z[valid], -y3[valid]], axis=1)
pts = cam @ Rtilt.T
print("size", w, h)
print("valid_depth", int(valid.sum()))
print("bounds_min", pts.min(0).tolist())
print("bounds_max", pts.max(0).tolist())
print("floor_q001", float(np.quantile(pts[:, 2], 0.001)), "ceiling_q999", float(np.quantile(pts[:, 2], 0.999)))

def inside_box(poly, pts, margin=0.0):
    X, Z = np.array(poly["X"]), np.array(poly["Z"])
    sgn = []
    for i in range(4):
        ax, ay, bx, by = X[i], Z[i], X[(i + 1) % 4], Z[(i + 1) % 4]
        ex, ey = bx - ax, by - ay
        cross = (ex * (pts[:, 1] - ay) - ey * (pts[:, 0] - ax)) / np.hypot(ex, ey)
        sgn.append(cross)
    sgn = np.stack(sgn, 1)
    ccw = np.all(sgn >= -margin, 1)
    cw = np.all(sgn <= margin, 1)
    zlo, zhi = -poly["Ymax"], -poly["Ymin"]
    return (ccw | cw) & (pts[:, 2] >= zlo - margin) & (pts[:, 2] <= zhi + margin)

def inside_rectangle(poly, pts, margin=0.0):
    """The cuboid convention of the crate, re-derived here: width axis along p1->p2, width |p2-p1|,
    depth |p3-p2|, centre = mean of the 4 corners (annotation quadrilaterals are not always exact
    rectangles, so this can differ slightly from the polygon test)."""
    X, Z = np.array(poly["X"]), np.array(poly["Z"])
    c = np.array([X.mean(), Z.mean()])
    e1 = np.array([X[1] - X[0], Z[1] - Z[0]]); w = np.linalg.norm(e1); a = e1 / w
    d = np.hypot(X[2] - X[1], Z[2] - Z[1])
    b = np.array([-a[1], a[0]])
    rel = pts[:, :2] - c
    s, t = rel @ a, rel @ b
    zlo, zhi = -poly["Ymax"], -poly["Ymin"]
    return (np.abs(s) <= w / 2 + margin) & (np.abs(t) <= d / 2 + margin) & \
        (pts[:, 2] >= zlo - margin) & (pts[:, 2] <= zhi + margin)

ann = json.load(open(os.path.join(d, "annotation3Dfinal", "index.json")))
for o in ann["objects"]:
    if o is None or not o.get("polygon"):
        continue
    poly = o["polygon"][0]
    n = int(inside_box(poly, pts).sum())
    # points within 1e-6 m of the box surface: a count that f32 rounding could change
    fuzzy = int(inside_box(poly, pts, 1e-6).sum()) - int(inside_box(poly, pts, -1e-6).sum())
    r = int(inside_rectangle(poly, pts).sum())
    rfuzzy = int(inside_rectangle(poly, pts, 1e-6).sum()) - int(inside_rectangle(poly, pts, -1e-6).sum())
    print("object", o["name"], "inside_polygon", n, "near_boundary", fuzzy, "inside_rectangle", r, "near_boundary", rfuzzy)

lay = json.load(open(os.path.join(d, "annotation3Dlayout", "index.json")))
room = [o for o in lay["objects"] if o and o.get("name") == "room"][0]["polygon"][0]
X, Y = np.array(room["X"]), np.array(room["Z"])
px, py = pts[:, 0], pts[:, 1]
inside = np.zeros(len(pts), bool)
j = len(X) - 1
for i in range(len(X)):
    cond = (Y[i] > py) != (Y[j] > py)
    xint = (X[j] - X[i]) * (py - Y[i]) / np.where(Y[j] - Y[i] == 0, 1e-300, Y[j] - Y[i]) + X[i]
    inside ^= cond & (px < xint)
    j = i
inside &= (pts[:, 2] >= -room["Ymax"]) & (pts[:, 2] <= -room["Ymin"])
print("layout_fraction_inside", float(inside.mean()), "floor", -room["Ymax"], "ceiling", -room["Ymin"])
