"""Blob extraction: connected components of thresholded pixels in ROI canvases (paper 002 sec. 5, [26]).

A blob is an 8-connected set of pixels above the detection threshold with at least `min_pixels`
pixels. Its photometry uses the aperture = the blob's bounding box grown by one pixel (clipped
to its canvas), which holds every pixel the body touches, so that faint edge pixels below the
threshold still count and the area is unbiased:
    area_px = sum(I) / signal_e,   centroid = sum(I * pixel centre) / sum(I)   over the aperture,
    area_sigma_px = sqrt(n_aperture * read_noise^2 + sum(I)) / signal_e  (read + photon noise).
Pixel (row i, col j) has its centre at (u, v) = (j + 0.5, i + 0.5).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from swarmhil.agent.camera.render import Detector, RoiStack, silhouette_area_px

_PLANAR_8 = np.zeros((3, 3, 3), dtype=bool)
_PLANAR_8[1] = True  # 8-connectivity within a canvas, none across canvases of a stack


@dataclass
class Blobs:
    """M blobs, sorted by (v, u) of their centroid. centroid_px (M, 2) = (u, v); bbox_px (M, 4) =
    row0, col0, row1, col1 (exclusive) of the thresholded pixels, in frame pixels."""

    centroid_px: np.ndarray
    area_px: np.ndarray
    area_sigma_px: np.ndarray
    n_pixels: np.ndarray
    bbox_px: np.ndarray

    def __len__(self) -> int:
        return len(self.area_px)

    @staticmethod
    def empty() -> "Blobs":
        return Blobs(np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros((0, 4), dtype=np.int64))

    @staticmethod
    def concat(parts: list["Blobs"]) -> "Blobs":
        if not parts:
            return Blobs.empty()
        if len(parts) == 1:
            return parts[0]
        b = Blobs(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("centroid_px", "area_px", "area_sigma_px", "n_pixels", "bbox_px")))
        order = np.lexsort((b.centroid_px[:, 0], b.centroid_px[:, 1]))
        return Blobs(b.centroid_px[order], b.area_px[order], b.area_sigma_px[order], b.n_pixels[order], b.bbox_px[order])


def blobs_in_stack(
    image_e: np.ndarray, origin_px: np.ndarray, size_px: np.ndarray, detector: Detector, min_pixels: int = 2, backend: str = "numpy"
) -> Blobs:
    """Blobs of a stack of canvases image_e (G, H, W) whose valid parts are size_px (G, 2) at origin_px (G, 2).

    backend "numpy": scipy.ndimage labelling; "numba": agent.camera._fast.blobs (same definition).
    """
    if backend == "numba":
        return _blobs_numba(image_e, origin_px, size_px, detector, min_pixels)
    labels, n = ndimage.label(image_e > detector.threshold_e, structure=_PLANAR_8)
    if n == 0:
        return Blobs.empty()
    counts = np.bincount(labels.ravel(), minlength=n + 1)[1:]
    slices = ndimage.find_objects(labels)
    box = np.array([(sl[0].start, sl[1].start, sl[2].start, sl[1].stop, sl[2].stop) for sl in slices], dtype=np.int64)
    keep = counts >= min_pixels
    if not keep.any():
        return Blobs.empty()
    box, counts = box[keep], counts[keep]
    g = box[:, 0]
    lim_r, lim_c = size_px[g, 0], size_px[g, 1]
    r0 = np.maximum(box[:, 1] - 1, 0)
    c0 = np.maximum(box[:, 2] - 1, 0)
    r1 = np.minimum(box[:, 3] + 1, lim_r)
    c1 = np.minimum(box[:, 4] + 1, lim_c)
    _, h, w = image_e.shape
    ii = np.arange(h, dtype=float)[None, :, None] + 0.5
    jj = np.arange(w, dtype=float)[None, None, :] + 0.5
    moments = np.stack((image_e, image_e * jj, image_e * ii), axis=1)  # (G, 3, H, W)
    integral = np.zeros(moments.shape[:2] + (h + 1, w + 1))
    np.cumsum(np.cumsum(moments, axis=2), axis=3, out=integral[:, :, 1:, 1:])
    s = integral[g, :, r1, c1] - integral[g, :, r0, c1] - integral[g, :, r1, c0] + integral[g, :, r0, c0]  # (M, 3)
    flux, su, sv = s[:, 0], s[:, 1], s[:, 2]
    safe = np.where(flux > 0, flux, 1.0)
    org = origin_px[g]
    centroid = np.stack((su / safe + org[:, 1], sv / safe + org[:, 0]), axis=1)
    n_ap = (r1 - r0) * (c1 - c0)
    area = flux / detector.signal_e
    area_sigma = np.sqrt(n_ap * detector.read_noise_e**2 + np.maximum(flux, 0.0)) / detector.signal_e
    bbox = np.stack((box[:, 1] + org[:, 0], box[:, 2] + org[:, 1], box[:, 3] + org[:, 0], box[:, 4] + org[:, 1]), axis=1)
    order = np.lexsort((centroid[:, 0], centroid[:, 1]))
    return Blobs(centroid[order], area[order], area_sigma[order], counts[order], bbox[order])


def _blobs_numba(image_e, origin_px, size_px, detector: Detector, min_pixels: int) -> Blobs:
    from swarmhil.agent.camera import _fast  # camera extra: numba kernels, only with backend numba

    return Blobs(
        *_fast.blobs(
            np.ascontiguousarray(image_e), np.ascontiguousarray(origin_px), np.ascontiguousarray(size_px),
            detector.threshold_e, min_pixels, detector.signal_e, detector.read_noise_e,
        )
    )  # fmt: skip


def extract_blobs(stacks: list[RoiStack], detector: Detector, min_pixels: int = 2, backend: str = "numpy") -> Blobs:
    """Blobs of a rendered frame given as ROI canvases (`Renderer.render_rois`)."""
    return Blobs.concat([blobs_in_stack(st.image_e, st.origin_px, st.size_px, detector, min_pixels, backend) for st in stacks])


def extract_blobs_full(image_e: np.ndarray, detector: Detector, min_pixels: int = 2) -> Blobs:
    """Blobs of a full (H, W) frame (`Renderer.render_full`): the same labelling over every pixel."""
    h, w = image_e.shape
    return blobs_in_stack(image_e[None], np.zeros((1, 2), dtype=np.int64), np.array([[h, w]]), detector, min_pixels)


def exact_blobs(pos_cam_m: np.ndarray, rot_body_to_cam: np.ndarray, camera, shape) -> Blobs:
    """Paper 002's assumption (sec. 5): area and centroid measured exactly, no image.

    area = exact silhouette area (agent.camera.render.silhouette_area_px), centroid = projection of
    the body centre; one blob per body whose centre projects into the frame, never merged.
    """
    pos = np.asarray(pos_cam_m, dtype=float).reshape(-1, 3)
    keep = camera.in_fov(pos)
    if not keep.any():
        return Blobs.empty()
    pos, rot = pos[keep], np.asarray(rot_body_to_cam, dtype=float).reshape(-1, 3, 3)[keep]
    uv = camera.project(pos)
    area = silhouette_area_px(pos, rot, camera, shape)
    px = np.floor(uv).astype(np.int64)
    bbox = np.stack((px[:, 1], px[:, 0], px[:, 1] + 1, px[:, 0] + 1), axis=1)
    order = np.lexsort((uv[:, 0], uv[:, 1]))
    return Blobs(uv[order], area[order], np.zeros(len(area)), np.ones(len(area), dtype=np.int64), bbox[order])


def exact_blobs_many(pos_cam_m: np.ndarray, rot_body_to_cam: np.ndarray, offsets: np.ndarray, camera, shape) -> list[Blobs]:
    """`exact_blobs` of R scenes at once (the batch mode, issue 36): scene r's bodies are rows
    offsets[r]:offsets[r+1]. Each scene's Blobs equals its own `exact_blobs`, bit for bit: the
    projection and the silhouette areas are computed per body (elementwise, the same arithmetic for
    one body among many: tests/test_batch_camera.py), the order is the same stable sort on (v, u)
    within each scene."""
    pos = np.asarray(pos_cam_m, dtype=float).reshape(-1, 3)
    rot = np.asarray(rot_body_to_cam, dtype=float).reshape(-1, 3, 3)
    off = np.asarray(offsets, dtype=np.int64)
    n = len(off) - 1
    keep = camera.in_fov(pos)
    owner = np.repeat(np.arange(n), np.diff(off))[keep]
    pos, rot = pos[keep], rot[keep]
    if len(pos) == 0:
        return [Blobs.empty() for _ in range(n)]
    uv = camera.project(pos)
    area = silhouette_area_px(pos, rot, camera, shape)
    px = np.floor(uv).astype(np.int64)
    bbox = np.stack((px[:, 1], px[:, 0], px[:, 1] + 1, px[:, 0] + 1), axis=1)
    order = np.lexsort((uv[:, 0], uv[:, 1], owner))  # stable: within a scene, exact_blobs's order
    uv, area, bbox = uv[order], area[order], bbox[order]
    bounds = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(owner, minlength=n), out=bounds[1:])
    out = []
    for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist()):
        m = b - a
        out.append(Blobs(uv[a:b].copy(), area[a:b].copy(), np.zeros(m), np.ones(m, dtype=np.int64), bbox[a:b].copy())
                   if m else Blobs.empty())
    return out
