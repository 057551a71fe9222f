"""Anti-aliased silhouette rendering of spacecraft into regions of interest (ROI).

Exact pixel coverage. For a simple polygon P (Green's theorem, row by row),
    F(X, Y) = area(P & {x < X, y < Y}) = sum over edges of  integral_{edge, y < Y} min(x, X) dy,
and the coverage of pixel [j, j+1) x [i, i+1) is the mixed difference F(j+1,i+1) - F(j,i+1)
- F(j+1,i) + F(j,i). Along one edge x is linear in y, so the integral is closed-form; terms that
depend on X alone or Y alone cancel in the difference, leaving per edge
    G(X, Y) = L/(2 (hi-lo)) * clip(hi - X, 0, hi - lo)^2 + L * max(0, lo - X),
with L the edge's signed length in y below Y and [lo, hi] its x-range there.
The silhouette of a convex cuboid is the union of its front faces, which tile it, so summing G
over its silhouette edges (an edge between a front and a back face) gives its coverage. The
spacecraft is a union of cuboids (agent.camera.shape); their coverages are summed and clipped
to 1, which is exact except in pixels where two parts' boundaries overlap each other.

ROI path: each body's ROI is its projected bounding box plus `ROI_MARGIN_PX`, clipped to the
frame; overlapping ROIs are merged into one canvas (so blobs that touch merge, as on a real
detector). Canvases are rendered in batches of similar size; nothing is computed over a full
frame. `render_full` is the reference path for tests: every body over every pixel.

Pixel values are photo-electrons: signal_e * coverage, plus photon noise (Gaussian with variance
= signal) and read noise (`Detector`). Noise comes from a per-camera bank of standard normals,
shifted by a per-frame offset, so a pixel has the same noise in the ROI and full-frame paths.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agent.camera.model import Camera
from agent.camera.shape import SpacecraftShape

ROI_MARGIN_PX = 2
SMALL_CANVAS_PX = 32
Z_NEAR_M = 0.05
_CHUNK_ELEMENTS = 1 << 21
_SIGN = -1.0  # front faces run clockwise in (u, v) with v down: see tests/test_camera_render.py


@dataclass(frozen=True)
class Detector:
    """Detector and exposure. Defaults: a sunlit body fills a pixel with 2000 e-, read noise 10 e-,
    detection threshold 60 e- (6 sigma of read noise: 1e-9 false alarms per pixel)."""

    signal_e: float = 2000.0
    read_noise_e: float = 10.0
    threshold_e: float = 60.0
    seed: int = 0


class NoiseBank:
    """Standard normals (H, W) drawn once; frame k uses them rolled by a hashed offset."""

    def __init__(self, camera: Camera, seed: int) -> None:
        self.h, self.w = camera.height_px, camera.width_px
        self.seed = seed
        self.bank = np.random.default_rng(seed).standard_normal((self.h, self.w)).astype(np.float32)

    def offset(self, frame: int) -> tuple[int, int]:
        z = _splitmix64((self.seed * 0x9E3779B97F4A7C15 + frame) & 0xFFFFFFFFFFFFFFFF)
        return int(z % self.h), int((z >> 32) % self.w)

    def sample(self, frame: int, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        dr, dc = self.offset(frame)
        return self.bank[(rows + dr) % self.h, (cols + dc) % self.w]


def _splitmix64(x: int) -> int:
    x = (x + 0x9E3779B97F4A7C15) & 0xFFFFFFFFFFFFFFFF
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
    return x ^ (x >> 31)


@dataclass
class RoiStack:
    """Canvases of one size class: image_e (G, Hp, Wp) in electrons, zero outside each canvas.

    origin_px (G, 2) = (row0, col0) of each canvas in the frame; size_px (G, 2) = (rows, cols).
    members: indices (into the rendered scene) of the bodies imaged on each canvas.
    """

    image_e: np.ndarray
    origin_px: np.ndarray
    size_px: np.ndarray
    members: list[np.ndarray]


@dataclass
class Silhouettes:
    """Projected silhouette edges of S bodies: endpoints (S, E, 2) in pixels, weights (S, E)."""

    uv_a: np.ndarray
    uv_b: np.ndarray
    weight: np.ndarray
    bbox_px: np.ndarray  # (S, 4) u_min, v_min, u_max, v_max of the projected vertices
    valid: np.ndarray  # (S,) all vertices in front of the camera


def silhouettes(
    pos_cam_m: np.ndarray, rot_body_to_cam: np.ndarray, camera: Camera, shape: SpacecraftShape
) -> Silhouettes:
    """Project every body and return the boundary of its silhouette as directed edge pieces.

    1. A face is front-facing when the camera (origin) is on its outer side:
       n_body . (R^T p) + n_body . c < 0 for a point c of the face.
    2. Each part (convex cuboid) projects to a convex polygon bounded by its silhouette edges
       (between a front and a back face), directed so that the inside lies on their right in
       (u, v) (v down).
    3. The union's boundary is each part's boundary minus its pieces inside the other parts
       (Cyrus-Beck clipping of each edge against each other convex polygon).
    """
    pos = np.asarray(pos_cam_m, dtype=float).reshape(-1, 3)
    rot = np.asarray(rot_body_to_cam, dtype=float).reshape(-1, 3, 3)
    n_s = len(pos)
    verts = np.matmul(shape.vertices_m, rot.transpose(0, 2, 1)) + pos[:, None, :]  # (S, V, 3)
    zs = verts[..., 2]
    valid = zs.min(axis=1) > Z_NEAR_M
    eye_body = np.matmul(rot.transpose(0, 2, 1), pos[:, :, None])[..., 0]  # R^T p
    front = eye_body @ shape.normals.T + shape.face_offsets_m < 0.0  # (S, F)
    ed = shape.edges  # (P, 12, 4)
    w = front[:, ed[..., 2]].astype(float) - front[:, ed[..., 3]]  # (S, P, 12)
    z = np.where(valid[:, None], zs, 1.0)
    f = camera.focal_px
    uv = np.stack((verts[..., 0] / z * f + camera.cx, verts[..., 1] / z * f + camera.cy), axis=-1)
    bbox = np.concatenate((uv.min(axis=1), uv.max(axis=1)), axis=1)
    fwd = (w > 0)[..., None]
    p0 = np.where(fwd, uv[:, ed[..., 0]], uv[:, ed[..., 1]])  # (S, P, 12, 2) directed silhouette edges
    p1 = np.where(fwd, uv[:, ed[..., 1]], uv[:, ed[..., 0]])
    on = w != 0.0
    a, b = _union_pieces(p0, p1, on)
    wt = (on[..., None] & (b > a)).astype(float)  # (S, P, 12, K)
    d = p1 - p0
    ua = p0[..., None, :] + a[..., None] * d[..., None, :]
    ub = p0[..., None, :] + b[..., None] * d[..., None, :]
    ua, ub, wt = ua.reshape(n_s, -1, 2), ub.reshape(n_s, -1, 2), wt.reshape(n_s, -1)
    nz = wt != 0.0
    n_keep = max(1, int(nz.sum(axis=1).max(initial=0)))
    order = np.argsort(~nz, axis=1, kind="stable")[:, :n_keep]
    rows = np.arange(n_s)[:, None]
    return Silhouettes(ua[rows, order], ub[rows, order], wt[rows, order], bbox, valid)


def _union_pieces(p0: np.ndarray, p1: np.ndarray, on: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Parameter ranges [a, b] (S, P, 12, P) of each directed edge lying outside every other part.

    Edge e(t) = p0 + t (p1 - p0); part q's inside: cross(q1 - q0, x - q0) < 0 for all its edges.
    """
    n_p = p0.shape[1]
    d = p1 - p0
    q0 = p0[:, None, None, :, :, :]  # (S, 1, 1, Q, H, 2)
    qd = d[:, None, None, :, :, :]
    e0 = p0[:, :, :, None, None, :]  # (S, P, E, 1, 1, 2)
    ed = d[:, :, :, None, None, :]
    r = e0 - q0
    c0 = -(qd[..., 0] * r[..., 1] - qd[..., 1] * r[..., 0])  # inside where c0 + t c1 > 0
    c1 = -(qd[..., 0] * ed[..., 1] - qd[..., 1] * ed[..., 0])  # (S, P, E, Q, H)
    inactive = ~on[:, None, None, :, :]
    c0 = np.where(inactive, 1.0, c0)
    c1 = np.where(inactive, 0.0, c1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -c0 / c1
    t_in = np.max(np.where(c1 > 0, t, 0.0), axis=-1, initial=0.0)
    t_out = np.min(np.where(c1 < 0, t, 1.0), axis=-1, initial=1.0)
    never = np.any((c1 == 0) & (c0 <= 0), axis=-1)
    empty = never | (t_in >= t_out) | np.eye(n_p, dtype=bool)[None, :, None, :]
    lo = np.where(empty, 1.0, t_in)  # (S, P, E, Q) intervals inside other parts
    hi = np.where(empty, 1.0, t_out)
    order = np.argsort(lo, axis=-1)
    lo = np.take_along_axis(lo, order, -1)
    hi = np.take_along_axis(hi, order, -1)
    reach = np.maximum.accumulate(hi, axis=-1)
    prev = np.concatenate((np.zeros(lo.shape[:-1] + (1,)), reach), axis=-1)  # (..., Q + 1)
    start = prev
    stop = np.concatenate((np.maximum(prev[..., :-1], lo), np.ones(lo.shape[:-1] + (1,))), axis=-1)
    return start, np.maximum(stop, start)


def coverage(sil_a: np.ndarray, sil_b: np.ndarray, weight: np.ndarray, origin_px: np.ndarray, size_px: tuple[int, int]) -> np.ndarray:
    """Exact coverage (S, H, W) of pixels [origin, origin + size) by S silhouettes (module docstring).

    sil_a, sil_b: (S, E, 2) edge endpoints (u, v) in frame pixels; weight (S, E); origin_px (S, 2) = (row0, col0).
    """
    h, w = size_px
    s, e = weight.shape
    org = np.asarray(origin_px, dtype=float)
    ua = sil_a[..., 0] - org[:, 1:2]
    va = sil_a[..., 1] - org[:, 0:1]
    ub = sil_b[..., 0] - org[:, 1:2]
    vb = sil_b[..., 1] - org[:, 0:1]
    up = vb > va
    sgn = np.where(up, 1.0, -1.0) * weight
    y_lo, y_hi = np.minimum(va, vb), np.maximum(va, vb)
    x_lo = np.where(up, ua, ub)
    dy = y_hi - y_lo
    slope = np.divide(np.where(up, ub, ua) - x_lo, dy, out=np.zeros_like(dy), where=dy > 0)
    out = np.empty((s, h, w))
    rows_per_chunk = max(1, _CHUNK_ELEMENTS // max(1, s * e * (w + 1)) - 1)
    xs = np.arange(w + 1, dtype=float)
    g_prev = None
    i0 = 0
    while i0 <= h:
        i1 = min(h + 1, i0 + rows_per_chunk)
        ys = np.arange(i0, i1, dtype=float)
        g = _edge_sum(ys, xs, y_lo, y_hi, x_lo, slope, sgn)  # (S, i1-i0, W+1)
        if g_prev is not None:
            g = np.concatenate((g_prev, g), axis=1)
            r0 = i0 - 1
        else:
            r0 = i0
        d = np.diff(np.diff(g, axis=1), axis=2)
        out[:, r0 : r0 + d.shape[1], :] = d
        g_prev = g[:, -1:, :]
        i0 = i1
    np.multiply(out, -_SIGN, out=out)  # coverage = -DD F = +DD G, times the orientation sign
    return np.clip(out, 0.0, 1.0, out=out)


def _edge_sum(ys, xs, y_lo, y_hi, x_lo, slope, sgn) -> np.ndarray:
    """G(X=xs, Y=ys) summed over edges: (S, len(ys), len(xs))."""
    yt = np.clip(ys[None, None, :], y_lo[..., None], y_hi[..., None])  # (S, E, I)
    length = yt - y_lo[..., None]
    xa = x_lo[..., None]
    xb = xa + slope[..., None] * length
    lo, hi = np.minimum(xa, xb), np.maximum(xa, xb)
    width = hi - lo
    coef_a = sgn[..., None] * length / (2.0 * np.maximum(width, 1e-12))
    coef_b = sgn[..., None] * length
    t = hi[..., None] - xs  # (S, E, I, J)
    np.maximum(t, 0.0, out=t)
    np.minimum(t, width[..., None], out=t)
    np.square(t, out=t)
    r = lo[..., None] - xs
    np.maximum(r, 0.0, out=r)
    return np.einsum("sei,seij->sij", coef_a, t) + np.einsum("sei,seij->sij", coef_b, r)


def _roi_boxes(bbox_px: np.ndarray, camera: Camera) -> np.ndarray:
    """(S, 4) row0, col0, row1, col1 (exclusive) of each body's ROI, clipped to the frame."""
    m = ROI_MARGIN_PX
    col0 = np.floor(bbox_px[:, 0]) - m
    row0 = np.floor(bbox_px[:, 1]) - m
    col1 = np.ceil(bbox_px[:, 2]) + m
    row1 = np.ceil(bbox_px[:, 3]) + m
    box = np.stack((row0, col0, row1, col1), axis=1)
    lim = np.array([camera.height_px, camera.width_px, camera.height_px, camera.width_px], dtype=float)
    return np.clip(box, 0, lim).astype(np.int64)


def group_boxes(boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge overlapping boxes until none overlap: returns group of each box and the group boxes."""
    group = np.arange(len(boxes))
    gbox = boxes.copy()
    while True:
        over = (
            (gbox[:, None, 0] < gbox[None, :, 2])
            & (gbox[None, :, 0] < gbox[:, None, 2])
            & (gbox[:, None, 1] < gbox[None, :, 3])
            & (gbox[None, :, 1] < gbox[:, None, 3])
        )
        np.fill_diagonal(over, False)
        if not over.any():
            return group, gbox
        a, b = np.argwhere(over)[0]
        merged = np.concatenate((np.minimum(gbox[a, :2], gbox[b, :2]), np.maximum(gbox[a, 2:], gbox[b, 2:])))
        group[group == b] = a
        gbox[a] = merged
        keep = np.ones(len(gbox), dtype=bool)
        keep[b] = False
        gbox = gbox[keep]
        group = np.searchsorted(np.flatnonzero(keep), group)


class Renderer:
    """Renders scenes for one camera: ROI canvases (flight path) or a full frame (test path)."""

    def __init__(self, camera: Camera | None = None, shape: SpacecraftShape | None = None, detector: Detector | None = None) -> None:
        self.camera = camera or Camera()
        self.shape = shape or SpacecraftShape()
        self.detector = detector or Detector()
        self.noise = NoiseBank(self.camera, self.detector.seed)

    def _expose(self, cov: np.ndarray, frame: int, rows: np.ndarray, cols: np.ndarray, noise: bool) -> np.ndarray:
        det = self.detector
        signal = det.signal_e * cov
        if not noise:
            return signal
        sigma = np.sqrt(signal + det.read_noise_e**2)
        return signal + sigma * self.noise.sample(frame, rows, cols)

    def render_rois(self, pos_cam_m: np.ndarray, rot_body_to_cam: np.ndarray, frame: int = 0, noise: bool = True) -> list[RoiStack]:
        """Render the bodies into merged ROI canvases: one batch for all small canvases, one per large."""
        sil = silhouettes(pos_cam_m, rot_body_to_cam, self.camera, self.shape)
        boxes = _roi_boxes(sil.bbox_px, self.camera)
        seen = sil.valid & (boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])
        idx = np.flatnonzero(seen)
        if len(idx) == 0:
            return []
        group, gbox = group_boxes(boxes[idx])
        gsize = gbox[:, 2:] - gbox[:, :2]
        small = gsize.max(axis=1) <= SMALL_CANVAS_PX
        batches = [np.flatnonzero(small)] if small.any() else []
        batches += [np.array([g]) for g in np.flatnonzero(~small)]
        return [self._render_batch(sil, idx, group, gbox, gsize, gsel, frame, noise) for gsel in batches]

    def _render_batch(self, sil, idx, group, gbox, gsize, gsel, frame, noise) -> RoiStack:
        hp, wp = int(gsize[gsel, 0].max()), int(gsize[gsel, 1].max())
        if len(group) == len(gbox):  # no merged canvases: body k is alone on canvas k
            members = [idx[g : g + 1] for g in gsel]
            body = idx[gsel]
            starts = None
        else:
            members = [idx[group == g] for g in gsel]
            body = np.concatenate(members)
            counts = np.array([len(m) for m in members])
            starts = np.concatenate(([0], np.cumsum(counts)[:-1])) if len(body) > len(gsel) else None
        org = gbox[gsel, :2]
        org_b = org if starts is None else np.repeat(org, counts, axis=0)
        cov = coverage(sil.uv_a[body], sil.uv_b[body], sil.weight[body], org_b, (hp, wp))
        if starts is not None:
            cov = np.minimum(np.add.reduceat(cov, starts, axis=0), 1.0)
        rows = org[:, 0, None, None] + np.arange(hp)[None, :, None]
        cols = org[:, 1, None, None] + np.arange(wp)[None, None, :]
        img = self._expose(cov, frame, rows, cols, noise)
        if len(gsel) > 1:
            size = gsize[gsel]
            img *= (rows - org[:, 0, None, None] < size[:, 0, None, None]) & (cols - org[:, 1, None, None] < size[:, 1, None, None])
        return RoiStack(img, org.copy(), gsize[gsel].copy(), members)

    def render_full(self, pos_cam_m: np.ndarray, rot_body_to_cam: np.ndarray, frame: int = 0, noise: bool = True) -> np.ndarray:
        """Reference path: every body's coverage over the whole frame, summed, clipped, exposed (H, W)."""
        cam = self.camera
        sil = silhouettes(pos_cam_m, rot_body_to_cam, cam, self.shape)
        cov = np.zeros((cam.height_px, cam.width_px))
        for k in np.flatnonzero(sil.valid):
            cov += coverage(sil.uv_a[k : k + 1], sil.uv_b[k : k + 1], sil.weight[k : k + 1], np.zeros((1, 2)), (cam.height_px, cam.width_px))[0]
        np.minimum(cov, 1.0, out=cov)
        rows, cols = np.mgrid[0 : cam.height_px, 0 : cam.width_px]
        return self._expose(cov, frame, rows, cols, noise)


def compose_frame(stacks: list[RoiStack], camera: Camera) -> np.ndarray:
    """Paste ROI canvases into a full (H, W) frame, zero elsewhere (debug images, tests)."""
    frame = np.zeros((camera.height_px, camera.width_px))
    for st in stacks:
        for g, ((r0, c0), (h, w)) in enumerate(zip(st.origin_px, st.size_px)):
            frame[r0 : r0 + h, c0 : c0 + w] = st.image_e[g, :h, :w]
    return frame


def silhouette_area_px(pos_cam_m: np.ndarray, rot_body_to_cam: np.ndarray, camera: Camera, shape: SpacecraftShape) -> np.ndarray:
    """Exact projected area (S,) in px^2 of each body's silhouette (shoelace over its boundary)."""
    sil = silhouettes(pos_cam_m, rot_body_to_cam, camera, shape)
    cross = sil.uv_a[..., 0] * sil.uv_b[..., 1] - sil.uv_b[..., 0] * sil.uv_a[..., 1]
    return np.where(sil.valid, _SIGN * 0.5 * np.sum(sil.weight * cross, axis=1), 0.0)
