"""Compiled (numba) twin of agent.camera.render's silhouette + rasteriser, same equations.

Optional: used by `Renderer(backend="numba")` when numba is installed; the numpy code in
agent.camera.render is the reference, and tests/test_camera_render.py checks that both agree.
"""
from __future__ import annotations

import numpy as np

from swarmhil.bus.optional import require

njit = require("numba", "[nav] backend = 'numba'").njit

_Z_NEAR_M = 0.05
_MAX_EDGES = 6
_SIGN = -1.0


@njit(cache=True)
def bboxes(verts_body, pos, rot, f, cx, cy):
    """(S, 4) u_min, v_min, u_max, v_max of the projected vertices and (S,) all-in-front flags."""
    n_s, n_v = pos.shape[0], verts_body.shape[0]
    box = np.empty((n_s, 4))
    valid = np.ones(n_s, dtype=np.bool_)
    for s in range(n_s):
        umin, vmin, umax, vmax = np.inf, np.inf, -np.inf, -np.inf
        for v in range(n_v):
            x = rot[s, 0, 0] * verts_body[v, 0] + rot[s, 0, 1] * verts_body[v, 1] + rot[s, 0, 2] * verts_body[v, 2] + pos[s, 0]
            y = rot[s, 1, 0] * verts_body[v, 0] + rot[s, 1, 1] * verts_body[v, 1] + rot[s, 1, 2] * verts_body[v, 2] + pos[s, 1]
            z = rot[s, 2, 0] * verts_body[v, 0] + rot[s, 2, 1] * verts_body[v, 1] + rot[s, 2, 2] * verts_body[v, 2] + pos[s, 2]
            if not z > _Z_NEAR_M:
                valid[s] = False
                z = 1.0
            u = x * (f / z) + cx
            w = y * (f / z) + cy
            umin, umax = min(umin, u), max(umax, u)
            vmin, vmax = min(vmin, w), max(vmax, w)
        box[s, 0], box[s, 1], box[s, 2], box[s, 3] = umin, vmin, umax, vmax
    return box, valid


@njit(cache=True)
def _phi(t):
    if t <= 0.0:
        return 0.0
    if t >= 1.0:
        return t - 0.5
    return 0.5 * t * t


@njit(cache=True)
def _raster_piece(ua, va, ub, vb, g, h_lim, w_lim, cover, part):
    if not (va != vb):
        return
    vmin, vmax = min(va, vb), max(va, vb)
    r_lo = max(int(np.floor(vmin)), 0)
    r_hi = min(int(np.ceil(vmax)) - 1, h_lim - 1)
    slope = (ub - ua) / (vb - va)
    for row in range(r_lo, r_hi + 1):
        ya = min(max(va, row), row + 1)
        yb = min(max(vb, row), row + 1)
        xa = ua + slope * (ya - va)
        xb = ua + slope * (yb - va)
        dy = yb - ya
        j0 = int(np.floor(min(xa, xb)))
        j1 = min(int(np.floor(max(xa, xb))), w_lim - 1)
        cover[g, row, min(max(j0, 0), w_lim)] -= dy
        for col in range(max(j0, 0), j1 + 1):
            ta, tb = xa - col, xb - col
            width = tb - ta
            if abs(width) < 1e-9:
                mean = min(max(0.5 * (ta + tb), 0.0), 1.0)
            else:
                mean = (_phi(tb) - _phi(ta)) / width
            part[g, row, col] += dy * mean


@njit(cache=True)
def _body_pieces(verts_body, normals, offsets, edges, pos, rot, f, cx, cy, out_a, out_b):
    """Directed union-silhouette pieces of one body into out_a/out_b; returns their number."""
    n_v, n_f, n_p = verts_body.shape[0], normals.shape[0], edges.shape[0]
    uv = np.empty((n_v, 2))
    for v in range(n_v):
        x = rot[0, 0] * verts_body[v, 0] + rot[0, 1] * verts_body[v, 1] + rot[0, 2] * verts_body[v, 2] + pos[0]
        y = rot[1, 0] * verts_body[v, 0] + rot[1, 1] * verts_body[v, 1] + rot[1, 2] * verts_body[v, 2] + pos[1]
        z = rot[2, 0] * verts_body[v, 0] + rot[2, 1] * verts_body[v, 1] + rot[2, 2] * verts_body[v, 2] + pos[2]
        uv[v, 0] = x * (f / z) + cx
        uv[v, 1] = y * (f / z) + cy
    eye = np.empty(3)
    for k in range(3):
        eye[k] = rot[0, k] * pos[0] + rot[1, k] * pos[1] + rot[2, k] * pos[2]
    front = np.empty(n_f, dtype=np.int8)
    for fi in range(n_f):
        front[fi] = 1 if eye[0] * normals[fi, 0] + eye[1] * normals[fi, 1] + eye[2] * normals[fi, 2] + offsets[fi] < 0.0 else 0
    p0 = np.zeros((n_p, _MAX_EDGES, 2))
    dd = np.zeros((n_p, _MAX_EDGES, 2))
    on = np.zeros((n_p, _MAX_EDGES), dtype=np.bool_)
    for p in range(n_p):
        cnt = 0
        for e in range(edges.shape[1]):
            w = front[edges[p, e, 2]] - front[edges[p, e, 3]]
            if w == 0 or cnt >= _MAX_EDGES:
                continue
            ia, ib = (edges[p, e, 0], edges[p, e, 1]) if w > 0 else (edges[p, e, 1], edges[p, e, 0])
            p0[p, cnt, 0], p0[p, cnt, 1] = uv[ia, 0], uv[ia, 1]
            dd[p, cnt, 0], dd[p, cnt, 1] = uv[ib, 0] - uv[ia, 0], uv[ib, 1] - uv[ia, 1]
            on[p, cnt] = abs(dd[p, cnt, 0]) + abs(dd[p, cnt, 1]) > 1e-12
            cnt += 1
    lo = np.empty(n_p)
    hi = np.empty(n_p)
    n_out = 0
    for p in range(n_p):
        for e in range(_MAX_EDGES):
            if not on[p, e]:
                continue
            ex, ey, edx, edy = p0[p, e, 0], p0[p, e, 1], dd[p, e, 0], dd[p, e, 1]
            for q in range(n_p):
                t_in, t_out, never = 0.0, 1.0, q == p
                for h in range(_MAX_EDGES):
                    if never or not on[q, h]:
                        continue
                    qx, qy, qdx, qdy = p0[q, h, 0], p0[q, h, 1], dd[q, h, 0], dd[q, h, 1]
                    c0 = qdy * (ex - qx) - qdx * (ey - qy)
                    c1 = qdy * edx - qdx * edy
                    if c1 > 0:
                        t_in = max(t_in, -c0 / c1)
                    elif c1 < 0:
                        t_out = min(t_out, -c0 / c1)
                    elif c0 <= 0:
                        never = True
                if never or t_in >= t_out:
                    a_lo, a_hi = 1.0, 1.0
                else:
                    a_lo, a_hi = max(t_in, 0.0), min(t_out, 1.0)
                k = q  # insertion sort by start
                while k > 0 and lo[k - 1] > a_lo:
                    lo[k], hi[k] = lo[k - 1], hi[k - 1]
                    k -= 1
                lo[k], hi[k] = a_lo, a_hi
            start = 0.0
            for k in range(n_p + 1):
                stop = max(start, lo[k]) if k < n_p else 1.0
                if stop > start:
                    out_a[n_out, 0], out_a[n_out, 1] = ex + start * edx, ey + start * edy
                    out_b[n_out, 0], out_b[n_out, 1] = ex + stop * edx, ey + stop * edy
                    n_out += 1
                if k < n_p:
                    start = max(start, hi[k])
    return n_out


@njit(cache=True)
def render_canvases(verts_body, normals, offsets, edges, pos, rot, f, cx, cy, canvas, origin, size, hp, wp):
    """Coverage (G, hp, wp) of canvases (origin (G, 2) = row0, col0; size (G, 2)); body s drawn on
    canvas[s] (skipped if < 0)."""
    n_g = origin.shape[0]
    cover = np.zeros((n_g, hp, wp + 1))
    part = np.zeros((n_g, hp, wp + 1))
    n_p = edges.shape[0]
    out_a = np.empty((n_p * _MAX_EDGES * (n_p + 1), 2))
    out_b = np.empty_like(out_a)
    for s in range(pos.shape[0]):
        g = canvas[s]
        if g < 0:
            continue
        n = _body_pieces(verts_body, normals, offsets, edges, pos[s], rot[s], f, cx, cy, out_a, out_b)
        for k in range(n):
            _raster_piece(out_a[k, 0] - origin[g, 1], out_a[k, 1] - origin[g, 0], out_b[k, 0] - origin[g, 1], out_b[k, 1] - origin[g, 0], g, size[g, 0], size[g, 1], cover, part)
    out = np.empty((n_g, hp, wp))
    for g in range(n_g):
        for r in range(hp):
            run = 0.0
            for c in range(wp):
                run += cover[g, r, c]
                val = (run + part[g, r, c]) * _SIGN
                out[g, r, c] = min(max(val, 0.0), 1.0)
    return out


@njit(cache=True)
def expose(cov, bank, dr, dc, origin, size, signal_e, read_noise_e, with_noise):
    """Electrons per pixel of each canvas: signal + sqrt(signal + read^2) * bank[(r + dr) % H, (c + dc) % W];
    zero outside each canvas's valid size (the numpy path: Renderer._expose)."""
    n_g, hp, wp = cov.shape
    bh, bw = bank.shape
    img = np.zeros_like(cov)
    for g in range(n_g):
        for r in range(size[g, 0]):
            rr = (origin[g, 0] + r + dr) % bh
            for c in range(size[g, 1]):
                sig = signal_e * cov[g, r, c]
                if with_noise:
                    sig += np.sqrt(sig + read_noise_e * read_noise_e) * bank[rr, (origin[g, 1] + c + dc) % bw]
                img[g, r, c] = sig
    return img


@njit(cache=True)
def blobs(image, origin, size, threshold, min_pixels, signal_e, read_noise_e):
    """8-connected components above threshold in each canvas and their aperture photometry
    (agent.blob.blobs: bbox grown by 1 px, clipped to the canvas), in frame pixels. Returns
    centroid (M, 2) = (u, v), area_px, area_sigma_px, n_pixels, bbox (M, 4) = r0, c0, r1, c1."""
    n_g, hp, wp = image.shape
    label = np.zeros((hp, wp), dtype=np.bool_)
    stack = np.empty(hp * wp, dtype=np.int64)
    cap = 64
    out_i = np.empty((cap, 5), dtype=np.int64)
    out_f = np.empty((cap, 4))
    n = 0
    for g in range(n_g):
        h, w = size[g, 0], size[g, 1]
        label[:h, :w] = False
        for r0 in range(h):
            for c0 in range(w):
                if label[r0, c0] or not image[g, r0, c0] > threshold:
                    continue
                label[r0, c0] = True
                stack[0] = r0 * w + c0
                top = 1
                npx, rmin, rmax, cmin, cmax = 0, r0, r0, c0, c0
                while top > 0:
                    top -= 1
                    r, c = stack[top] // w, stack[top] % w
                    npx += 1
                    rmin, rmax, cmin, cmax = min(rmin, r), max(rmax, r), min(cmin, c), max(cmax, c)
                    for rr in range(max(r - 1, 0), min(r + 2, h)):
                        for cc in range(max(c - 1, 0), min(c + 2, w)):
                            if not label[rr, cc] and image[g, rr, cc] > threshold:
                                label[rr, cc] = True
                                stack[top] = rr * w + cc
                                top += 1
                if npx < min_pixels:
                    continue
                a0, a1 = max(rmin - 1, 0), min(rmax + 2, h)
                b0, b1 = max(cmin - 1, 0), min(cmax + 2, w)
                flux, su, sv = 0.0, 0.0, 0.0
                for rr in range(a0, a1):
                    for cc in range(b0, b1):
                        v = image[g, rr, cc]
                        flux += v
                        su += v * (cc + 0.5)
                        sv += v * (rr + 0.5)
                if n == cap:
                    cap *= 2
                    oi, of = np.empty((cap, 5), dtype=np.int64), np.empty((cap, 4))
                    oi[:n], of[:n] = out_i[:n], out_f[:n]
                    out_i, out_f = oi, of
                safe = flux if flux > 0 else 1.0
                out_i[n, 0] = npx
                out_i[n, 1], out_i[n, 2] = rmin + origin[g, 0], cmin + origin[g, 1]
                out_i[n, 3], out_i[n, 4] = rmax + 1 + origin[g, 0], cmax + 1 + origin[g, 1]
                out_f[n, 0] = su / safe + origin[g, 1]
                out_f[n, 1] = sv / safe + origin[g, 0]
                out_f[n, 2] = flux / signal_e
                out_f[n, 3] = np.sqrt((a1 - a0) * (b1 - b0) * read_noise_e * read_noise_e + max(flux, 0.0)) / signal_e
                n += 1
    out_i, out_f = out_i[:n], out_f[:n]
    order = np.arange(n)
    for i in range(1, n):  # insertion sort by (v, u) of the centroid, as np.lexsort((u, v))
        k = order[i]
        j = i
        while j > 0 and (out_f[order[j - 1], 1] > out_f[k, 1] or (out_f[order[j - 1], 1] == out_f[k, 1] and out_f[order[j - 1], 0] > out_f[k, 0])):
            order[j] = order[j - 1]
            j -= 1
        order[j] = k
    return out_f[order, :2], out_f[order, 2], out_f[order, 3], out_i[order, 0], out_i[order, 1:]


@njit(cache=True)
def plan_canvases(verts_body, pos, rot, f, cx, cy, height, width, margin):
    """ROI of each body (projected bbox + margin, clipped to the frame) merged into canvases until
    none overlap (agent.camera.render._roi_boxes and group_boxes). Returns canvas of each body
    (-1: not in view / behind the camera), canvas origins (G, 2) and sizes (G, 2)."""
    box, valid = bboxes(verts_body, pos, rot, f, cx, cy)
    n_s = pos.shape[0]
    canvas = np.full(n_s, -1, dtype=np.int64)
    g_box = np.empty((n_s, 4), dtype=np.int64)
    n_g = 0
    for s in range(n_s):
        r0 = min(max(np.floor(box[s, 1]) - margin, 0.0), height)
        c0 = min(max(np.floor(box[s, 0]) - margin, 0.0), width)
        r1 = min(max(np.ceil(box[s, 3]) + margin, 0.0), height)
        c1 = min(max(np.ceil(box[s, 2]) + margin, 0.0), width)
        if valid[s] and r1 > r0 and c1 > c0:
            g_box[n_g, 0], g_box[n_g, 1], g_box[n_g, 2], g_box[n_g, 3] = int(r0), int(c0), int(r1), int(c1)
            canvas[s] = n_g
            n_g += 1
    merged = True
    while merged:
        merged = False
        for i in range(n_g):
            for j in range(i + 1, n_g):
                if g_box[i, 0] < g_box[j, 2] and g_box[j, 0] < g_box[i, 2] and g_box[i, 1] < g_box[j, 3] and g_box[j, 1] < g_box[i, 3]:
                    for k in range(2):
                        g_box[i, k] = min(g_box[i, k], g_box[j, k])
                        g_box[i, k + 2] = max(g_box[i, k + 2], g_box[j, k + 2])
                    for k in range(4):
                        g_box[j, k] = g_box[n_g - 1, k]
                    for s in range(n_s):
                        if canvas[s] == j:
                            canvas[s] = i
                        elif canvas[s] == n_g - 1:
                            canvas[s] = j
                    n_g -= 1
                    merged = True
                    break
            if merged:
                break
    origin = np.ascontiguousarray(g_box[:n_g, :2])
    size = g_box[:n_g, 2:] - g_box[:n_g, :2]
    return canvas, origin, size
