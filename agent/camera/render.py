"""Anti-aliased silhouette rendering of spacecraft into regions of interest (ROI).

Exact pixel coverage (the signed-area rasteriser of font renderers). By Green's theorem the
area of a region inside pixel (row i, col j) = [j, j+1) x [i, i+1) is, over its directed
boundary, sum_e integral_{e, y in [i, i+1)} clamp(x(y) - j, 0, 1) dy. Per edge and row band:
  - pixels wholly left of the edge's x-range there get the edge's signed height dy in the band
    (the "cover", accumulated with a cumulative sum along the row);
  - pixels the edge crosses get dy * (Phi(x_b - j) - Phi(x_a - j)) / (x_b - x_a) with
    Phi(t) = integral_0^t clamp = 0, t^2/2, t - 1/2 for t <= 0, in [0, 1], >= 1;
  - pixels right of it get nothing.
Work is proportional to the boundary's length in pixels plus the canvas area (one cumsum).

Silhouette boundary. The spacecraft is a union of convex cuboids (agent.camera.shape). A cuboid
projects to a convex polygon bounded by its silhouette edges (between a front and a back face);
the union's boundary is each part's boundary minus its pieces inside the other parts
(Cyrus-Beck clipping), so the coverage of the whole body is exact. Bodies whose canvases overlap
share one canvas; their coverages add and are clipped to 1 (blobs that touch merge).

ROI path: a body's ROI is its projected bounding box plus `ROI_MARGIN_PX`, clipped to the frame;
overlapping ROIs merge into one canvas; all canvases of a frame are rendered together into one
zero-padded stack. `render_full` is the reference path for tests: one canvas = the whole frame.

Pixel values are photo-electrons: signal_e * coverage, plus photon noise (Gaussian with variance
= signal) and read noise (`Detector`). Noise comes from a per-camera bank of standard normals,
shifted by a per-frame offset, so a pixel has the same noise in the ROI and full-frame paths.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmhil.agent.camera.model import Camera
from swarmhil.agent.camera.shape import SpacecraftShape
from swarmhil.bus.optional import require

ROI_MARGIN_PX = 2
Z_NEAR_M = 0.05
MAX_SILHOUETTE_EDGES = 6  # a convex cuboid's outline is at most a hexagon
_SIGN = -1.0  # the boundary as directed here has negative shoelace area in (u, v), v down


@dataclass(frozen=True)
class Detector:
    """Detector and exposure. Defaults: a sunlit body fills a pixel with 2000 e-, read noise 10 e-,
    detection threshold 60 e- (6 sigma of read noise: 1e-9 false alarms per pixel)."""

    signal_e: float = 2000.0
    read_noise_e: float = 10.0
    threshold_e: float = 60.0
    seed: int = 0


_BANKS: dict[tuple[int, int, int], np.ndarray] = {}  # (seed, H, W) -> the read-only bank, drawn once per process


class NoiseBank:
    """Standard normals (H, W) drawn once; frame k uses them rolled by a hashed offset. The draw is
    a function of (seed, H, W) alone, so the cameras of a process share one read-only bank, drawn
    on first use (an exact-imaging pipeline never draws it; the batch mode's 20 pipelines draw it once)."""

    def __init__(self, camera: Camera, seed: int) -> None:
        self.h, self.w = camera.height_px, camera.width_px
        self.seed = seed

    @property
    def bank(self) -> np.ndarray:
        key = (int(self.seed), self.h, self.w)
        b = _BANKS.get(key)
        if b is None:
            b = _BANKS[key] = np.random.default_rng(self.seed).standard_normal((self.h, self.w)).astype(np.float32)
            b.setflags(write=False)
        return b

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
    """Canvases of a frame: image_e (G, Hp, Wp) in electrons, zero outside each canvas.

    origin_px (G, 2) = (row0, col0) of each canvas in the frame; size_px (G, 2) = (rows, cols).
    bodies: indices (into the rendered scene) of the bodies imaged; canvas_of: their canvases.
    """

    image_e: np.ndarray
    origin_px: np.ndarray
    size_px: np.ndarray
    bodies: np.ndarray
    canvas_of: np.ndarray

    @property
    def members(self) -> list[np.ndarray]:
        """Scene indices of the bodies on each canvas."""
        return [self.bodies[self.canvas_of == g] for g in range(len(self.origin_px))]


@dataclass
class Silhouettes:
    """Boundary pieces of S bodies' silhouettes, flat: piece k of body body[k] runs a[k] -> b[k]
    ((N, 2) pixel coordinates u, v); bbox_px (S, 4) = u_min, v_min, u_max, v_max of the vertices."""

    body: np.ndarray
    a: np.ndarray
    b: np.ndarray
    bbox_px: np.ndarray
    valid: np.ndarray  # (S,) every vertex in front of the camera


def silhouettes(pos_cam_m: np.ndarray, rot_body_to_cam: np.ndarray, camera: Camera, shape: SpacecraftShape) -> Silhouettes:
    """Project the bodies and return the directed boundary of each one's silhouette (module docstring).

    A face is front-facing when the camera (origin) is on its outer side:
    n_body . (R^T p) + n_body . c < 0 for a point c of the face.
    """
    pos = np.asarray(pos_cam_m, dtype=float).reshape(-1, 3)
    rot = np.asarray(rot_body_to_cam, dtype=float).reshape(-1, 3, 3)
    n_s = len(pos)
    rot_t = rot.transpose(0, 2, 1)
    verts = np.matmul(shape.vertices_m, rot_t)
    verts += pos[:, None, :]  # (S, V, 3)
    zs = verts[..., 2]
    valid = zs.min(axis=1) > Z_NEAR_M
    eye_body = np.matmul(pos[:, None, :], rot)[:, 0, :]  # R^T p
    front = (eye_body @ shape.normals.T + shape.face_offsets_m < 0.0).view(np.int8)  # (S, F)
    ed = shape.edges  # (P, 12, 4)
    w = front[:, ed[..., 2]] - front[:, ed[..., 3]]  # (S, P, 12)
    z = np.where(valid[:, None], zs, 1.0)
    scale = camera.focal_px / z
    uv = verts[..., :2] * scale[..., None]
    uv += (camera.cx, camera.cy)  # (S, V, 2)
    bbox = np.concatenate((uv.min(axis=1), uv.max(axis=1)), axis=1)
    # keep each part's silhouette edges (at most 6), directed with the inside on their right
    order = np.argsort(w == 0, axis=2, kind="stable")[..., :MAX_SILHOUETTE_EDGES]  # (S, P, 6)
    s_ix = np.arange(n_s)[:, None, None]
    p_ix = np.arange(ed.shape[0])[None, :, None]
    w = w[s_ix, p_ix, order]
    e_sel = ed[p_ix, order]  # (S, P, 6, 4)
    fwd = w > 0
    p0 = uv[s_ix, np.where(fwd, e_sel[..., 0], e_sel[..., 1])]  # (S, P, 6, 2)
    p1 = uv[s_ix, np.where(fwd, e_sel[..., 1], e_sel[..., 0])]
    d = p1 - p0
    on = (w != 0) & (np.abs(d).sum(axis=-1) > 1e-12)
    on &= valid[:, None, None]
    t0, t1 = _union_pieces(p0, d, on)  # (S, P, 6, K)
    keep = (t1 > t0) & on[..., None]
    s_idx, p_idx, e_idx, _ = np.nonzero(keep)
    p0k, dk = p0[s_idx, p_idx, e_idx], d[s_idx, p_idx, e_idx]
    a = p0k + t0[keep][:, None] * dk
    b = p0k + t1[keep][:, None] * dk
    return Silhouettes(s_idx, a, b, bbox, valid)


def _union_pieces(p0: np.ndarray, d: np.ndarray, on: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Parameter ranges [t0, t1] (S, P, E, P) of each directed edge lying outside every other part.

    Edge e(t) = p0 + t d; part q's inside: cross(d_h, x - q0_h) < 0 for all its edges h. Arrays are
    laid out (H, S, P, E, Q) so that the reductions over the half-planes h are element-wise.
    """
    n_p = p0.shape[1]
    qx, qy = (np.moveaxis(p0[..., k], 2, 0)[:, :, None, None, :] for k in (0, 1))  # (H, S, 1, 1, Q)
    qdx, qdy = (np.moveaxis(d[..., k], 2, 0)[:, :, None, None, :] for k in (0, 1))
    ex, ey = p0[None, ..., 0, None], p0[None, ..., 1, None]  # (1, S, P, E, 1)
    edx, edy = d[None, ..., 0, None], d[None, ..., 1, None]
    c0 = qdy * (ex - qx) - qdx * (ey - qy)  # inside where c0 + t c1 > 0
    c1 = qdy * edx - qdx * edy
    off = ~np.moveaxis(on, 2, 0)[:, :, None, None, :]
    c0[np.broadcast_to(off, c0.shape)] = 1.0
    c1[np.broadcast_to(off, c1.shape)] = 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -c0 / c1
    t_in = np.where(c1 > 0, t, 0.0).max(axis=0)
    t_out = np.where(c1 < 0, t, 1.0).min(axis=0)
    never = ((c1 == 0) & (c0 <= 0)).any(axis=0)
    empty = never | (t_in >= t_out) | np.eye(n_p, dtype=bool)[None, :, None, :]
    lo = np.where(empty, 1.0, np.maximum(t_in, 0.0))  # (S, P, E, Q) inside other parts
    hi = np.where(empty, 1.0, np.minimum(t_out, 1.0))
    order = np.argsort(lo, axis=-1)
    ix = np.indices(lo.shape, sparse=True)
    lo = lo[ix[0], ix[1], ix[2], order]
    reach = np.maximum.accumulate(hi[ix[0], ix[1], ix[2], order], axis=-1)
    start = np.concatenate((np.zeros(lo.shape[:-1] + (1,)), reach), axis=-1)  # gaps between them
    stop = np.concatenate((np.maximum(start[..., :-1], lo), np.ones(lo.shape[:-1] + (1,))), axis=-1)
    return start, stop


def rasterize(a: np.ndarray, b: np.ndarray, canvas: np.ndarray, size_px: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    """Coverage (G, H, W) of canvases by directed boundaries (module docstring).

    a, b: (N, 2) piece endpoints (u, v) in each piece's canvas coordinates; canvas: (N,) canvas
    index of each piece; size_px (G, 2) = valid rows, cols of each canvas; shape = (G, H, W).
    """
    n_g, hp, wp = shape
    vmin, vmax = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
    h_lim = size_px[canvas, 0]
    r_lo = np.maximum(np.floor(vmin), 0).astype(np.int64)
    r_hi = np.minimum(np.ceil(vmax).astype(np.int64) - 1, h_lim - 1)
    n_rows = np.maximum(r_hi - r_lo + 1, 0) * (vmax > vmin)
    k = np.repeat(np.arange(len(a)), n_rows)  # one entry per (piece, row band)
    row = r_lo[k] + np.arange(len(k)) - np.repeat(np.cumsum(n_rows) - n_rows, n_rows)
    ua, va, ub, vb = a[k, 0], a[k, 1], b[k, 0], b[k, 1]
    ya = np.clip(va, row, row + 1)
    yb = np.clip(vb, row, row + 1)
    slope = (ub - ua) / (vb - va)
    xa = ua + slope * (ya - va)
    xb = ua + slope * (yb - va)
    dy = yb - ya
    w_lim = size_px[canvas[k], 1]
    j0 = np.floor(np.minimum(xa, xb)).astype(np.int64)
    j1 = np.minimum(np.floor(np.maximum(xa, xb)).astype(np.int64), w_lim - 1)
    base = (canvas[k] * hp + row) * (wp + 1)
    n_acc = n_g * hp * (wp + 1)
    cover = np.bincount(base + np.clip(j0, 0, w_lim), weights=-dy, minlength=n_acc)
    j_first = np.maximum(j0, 0)
    n_cols = np.maximum(j1 - j_first + 1, 0)
    m = np.repeat(np.arange(len(k)), n_cols)  # one entry per (piece, row band, crossed pixel)
    col = j_first[m] + np.arange(len(m)) - np.repeat(np.cumsum(n_cols) - n_cols, n_cols)
    ta, tb = xa[m] - col, xb[m] - col
    width = tb - ta
    thin = np.abs(width) < 1e-9
    mean = np.where(thin, np.clip(0.5 * (ta + tb), 0.0, 1.0), (_phi(tb) - _phi(ta)) / np.where(thin, 1.0, width))
    part = np.bincount(base[m] + col, weights=dy[m] * mean, minlength=n_acc)
    # float64 even when no piece crosses a row (np.bincount of an empty input is int64)
    cov = np.cumsum(cover.reshape(n_g, hp, wp + 1), axis=2, dtype=np.float64)
    cov += part.reshape(n_g, hp, wp + 1)
    cov = cov[..., :wp]
    cov *= _SIGN  # the boundary runs clockwise (negative orientation) in (u, v)
    return np.clip(cov, 0.0, 1.0, out=cov)


def _phi(t: np.ndarray) -> np.ndarray:
    """Integral of clamp(., 0, 1) from 0 to t."""
    c = np.clip(t, 0.0, 1.0)
    return 0.5 * c * c + np.maximum(t - 1.0, 0.0)


def _roi_boxes(bbox_px: np.ndarray, camera: Camera) -> np.ndarray:
    """(S, 4) row0, col0, row1, col1 (exclusive) of each body's ROI, clipped to the frame."""
    m = ROI_MARGIN_PX
    lo = np.floor(bbox_px[:, 1::-1]) - m  # row0, col0
    hi = np.ceil(bbox_px[:, :1:-1]) + m  # row1, col1
    lim = np.array([camera.height_px, camera.width_px], dtype=float)
    box = np.concatenate((lo, hi), axis=1)
    return np.minimum(np.maximum(box, 0.0), np.tile(lim, 2)).astype(np.int64)


def group_boxes(boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge overlapping boxes until none overlap: returns the group of each box and the group boxes."""
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
        i, j = np.argwhere(over)[0]
        gbox[i] = np.concatenate((np.minimum(gbox[i, :2], gbox[j, :2]), np.maximum(gbox[i, 2:], gbox[j, 2:])))
        group[group == j] = i
        keep = np.arange(len(gbox)) != j
        gbox = gbox[keep]
        group = np.searchsorted(np.flatnonzero(keep), group)


class Renderer:
    """Renders scenes for one camera: ROI canvases (flight path) or a full frame (test path).

    backend: "numpy" (reference) or "numba" (agent.camera._fast, the same equations compiled;
    numba is a core dependency). "auto" picks numba when it can be imported.
    """

    def __init__(
        self,
        camera: Camera | None = None,
        shape: SpacecraftShape | None = None,
        detector: Detector | None = None,
        backend: str = "numpy",
    ) -> None:
        self.camera = camera or Camera()
        self.shape = shape or SpacecraftShape()
        self.detector = detector or Detector()
        self.noise = NoiseBank(self.camera, self.detector.seed)
        self.backend = _pick_backend(backend)

    def _expose(self, cov: np.ndarray, frame: int, rows: np.ndarray, cols: np.ndarray, noise: bool) -> np.ndarray:
        det = self.detector
        signal = det.signal_e * cov
        if not noise:
            return signal
        sigma = np.sqrt(signal + det.read_noise_e**2)
        return signal + sigma * self.noise.sample(frame, rows, cols)

    def _coverage(self, pos, rot, canvas_of_body, origin, size, hp, wp, sil=None) -> np.ndarray:
        cam, shp = self.camera, self.shape
        if self.backend == "numba":
            from swarmhil.agent.camera import _fast  # camera extra: numba kernels, only with backend numba

            return _fast.render_canvases(
                shp.vertices_m, shp.normals, shp.face_offsets_m, shp.edges, pos, rot,
                cam.focal_px, cam.cx, cam.cy, canvas_of_body, origin, size, hp, wp,
            )  # fmt: skip
        sil = sil or silhouettes(pos, rot, cam, shp)
        pc = canvas_of_body[sil.body]
        sel = pc >= 0
        pc = pc[sel]
        org_uv = origin[pc][:, ::-1]  # (col0, row0) of each piece's canvas
        return rasterize(sil.a[sel] - org_uv, sil.b[sel] - org_uv, pc, size, (len(origin), hp, wp))

    def render_rois(self, pos_cam_m: np.ndarray, rot_body_to_cam: np.ndarray, frame: int = 0, noise: bool = True) -> list[RoiStack]:
        """Render the bodies into merged ROI canvases, all in one zero-padded stack."""
        cam = self.camera
        pos = np.ascontiguousarray(pos_cam_m, dtype=float).reshape(-1, 3)
        rot = np.ascontiguousarray(rot_body_to_cam, dtype=float).reshape(-1, 3, 3)
        if self.backend == "numba":
            return self._render_rois_numba(pos, rot, frame, noise)
        sil = silhouettes(pos, rot, cam, self.shape)
        boxes = _roi_boxes(sil.bbox_px, cam)
        seen = sil.valid & (boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])
        idx = np.flatnonzero(seen)
        if len(idx) == 0:
            return []
        group, gbox = group_boxes(boxes[idx])
        size = gbox[:, 2:] - gbox[:, :2]
        canvas_of_body = np.full(len(boxes), -1, dtype=np.int64)
        canvas_of_body[idx] = group
        origin = np.ascontiguousarray(gbox[:, :2])
        hp, wp = int(size[:, 0].max()), int(size[:, 1].max())
        cov = self._coverage(pos, rot, canvas_of_body, origin, size, hp, wp, sil)
        rr = np.arange(hp)[None, :, None]
        cc = np.arange(wp)[None, None, :]
        img = self._expose(cov, frame, origin[:, 0, None, None] + rr, origin[:, 1, None, None] + cc, noise)
        if len(gbox) > 1:
            img *= (rr < size[:, 0, None, None]) & (cc < size[:, 1, None, None])
        return [RoiStack(img, origin, size, idx, group)]

    def _render_rois_numba(self, pos: np.ndarray, rot: np.ndarray, frame: int, noise: bool) -> list[RoiStack]:
        from swarmhil.agent.camera import _fast  # camera extra: numba kernels, only with backend numba

        cam, shp, det = self.camera, self.shape, self.detector
        canvas, origin, size = _fast.plan_canvases(shp.vertices_m, pos, rot, cam.focal_px, cam.cx, cam.cy, cam.height_px, cam.width_px, ROI_MARGIN_PX)
        if len(origin) == 0:
            return []
        hp, wp = int(size[:, 0].max()), int(size[:, 1].max())
        cov = self._coverage(pos, rot, canvas, origin, size, hp, wp)
        dr, dc = self.noise.offset(frame)
        img = _fast.expose(cov, self.noise.bank, dr, dc, origin, size, det.signal_e, det.read_noise_e, noise)
        idx = np.flatnonzero(canvas >= 0)
        return [RoiStack(img, origin, size, idx, canvas[idx])]

    def render_full(self, pos_cam_m: np.ndarray, rot_body_to_cam: np.ndarray, frame: int = 0, noise: bool = True) -> np.ndarray:
        """Reference path: the whole frame as one canvas (H, W)."""
        cam = self.camera
        pos = np.ascontiguousarray(pos_cam_m, dtype=float).reshape(-1, 3)
        rot = np.ascontiguousarray(rot_body_to_cam, dtype=float).reshape(-1, 3, 3)
        h, w = cam.height_px, cam.width_px
        cov = self._coverage(pos, rot, np.zeros(len(pos), dtype=np.int64), np.zeros((1, 2), dtype=np.int64), np.array([[h, w]]), h, w)[0]
        rows, cols = np.mgrid[0:h, 0:w]
        return self._expose(cov, frame, rows, cols, noise)


def _pick_backend(backend: str) -> str:
    if backend not in ("numpy", "numba", "auto"):
        raise ValueError(f"unknown render backend {backend!r}; known: numpy, numba, auto")
    if backend == "numpy":
        return backend

    try:
        require("numba", f"[nav] backend = {backend!r}")
    except ImportError:
        if backend == "numba":
            raise
        return "numpy"  # "auto" without numba: the numpy reference, same equations
    return "numba"


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
    cross = sil.a[:, 0] * sil.b[:, 1] - sil.b[:, 0] * sil.a[:, 1]
    n = len(np.atleast_2d(np.asarray(pos_cam_m)))
    return _SIGN * 0.5 * np.bincount(sil.body, weights=cross, minlength=n)
