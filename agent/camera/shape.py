"""Spacecraft silhouette model of paper 002 section 5: a 20 cm cube body with two 50 cm solar panels.

The paper gives the body (a 20 cm square) and the panels (50 cm each), not the panel width.
Assumed here: each panel is 0.50 m long (span) x 0.20 m wide (the body's side) x 0.02 m thick,
attached to the middle of two opposite body faces, so the spacecraft spans 1.20 m x 0.20 m.

Body frame = the spacecraft's own camera frame when it points nominally (x right = -z LVLH,
y down = -x LVLH, z forward = +y LVLH; see `agent.camera.model`). The panels span body +-x
(cross-track, "lateral"), are 0.20 m along body y (radial) and thin along body z (along-track):
a neighbour ahead or behind sees them face-on, a 1.20 m x 0.20 m bar of area 0.24 m^2.

The model is a union of P cuboids (parts). Each cuboid is described by its 8 vertices, 6 faces (outward
normals, vertices counter-clockwise about the normal) and 12 edges with their left/right faces,
which is what the silhouette renderer needs (agent.camera.render).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# Vertex k of a unit cuboid has bits (bx, by, bz) = ((k >> 2) & 1, (k >> 1) & 1, k & 1).
_BITS = np.array([[(k >> 2) & 1, (k >> 1) & 1, k & 1] for k in range(8)], dtype=float)
_CUBE_FACES = np.array(
    [
        [4, 6, 7, 5],  # +x
        [0, 1, 3, 2],  # -x
        [2, 3, 7, 6],  # +y
        [0, 4, 5, 1],  # -y
        [1, 5, 7, 3],  # +z
        [0, 2, 6, 4],  # -z
    ]
)
_CUBE_NORMALS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)


@dataclass(frozen=True)
class SpacecraftShape:
    body_side_m: float = 0.20
    panel_length_m: float = 0.50
    panel_width_m: float = 0.20
    panel_thickness_m: float = 0.02
    vertices_m: np.ndarray = field(init=False, repr=False)  # (V, 3) body frame
    faces: np.ndarray = field(init=False, repr=False)  # (F, 4) vertex indices, CCW about the normal
    normals: np.ndarray = field(init=False, repr=False)  # (F, 3) outward unit normals
    edges: np.ndarray = field(init=False, repr=False)  # (P, 12, 4): per part, vertex a, vertex b, face left, face right
    face_offsets_m: np.ndarray = field(init=False, repr=False)  # (F,) n . (a vertex of the face)

    def __post_init__(self) -> None:
        s, l, w, t = self.body_side_m, self.panel_length_m, self.panel_width_m, self.panel_thickness_m
        centres = [(0.0, 0.0, 0.0), (s / 2 + l / 2, 0.0, 0.0), (-(s / 2 + l / 2), 0.0, 0.0)]
        sizes = [(s, s, s), (l, w, t), (l, w, t)]
        verts, faces, normals = [], [], []
        for k, (c, size) in enumerate(zip(centres, sizes)):
            verts.append(np.asarray(c) + (_BITS - 0.5) * np.asarray(size))
            faces.append(_CUBE_FACES + 8 * k)
            normals.append(_CUBE_NORMALS)
        v = np.concatenate(verts)
        f = np.concatenate(faces)
        object.__setattr__(self, "vertices_m", v)
        object.__setattr__(self, "faces", f)
        nrm = np.concatenate(normals)
        object.__setattr__(self, "normals", nrm)
        object.__setattr__(self, "face_offsets_m", np.einsum("fi,fi->f", nrm, v[f[:, 0]]))
        tables = [_edge_table(fk) + np.array([0, 0, 6 * k, 6 * k]) for k, fk in enumerate(faces)]
        object.__setattr__(self, "edges", np.stack(tables))  # global vertex and face indices

    @property
    def projected_areas_m2(self) -> np.ndarray:
        """Extra silhouette area per unit |x|/z, |y|/z and the face-on area: (A_x, A_y, A_z).

        Seen slightly off-axis, a body in nominal attitude shows its face-on silhouette A_z plus
        the faces turned towards the camera that nothing hides: along x only the panel end
        (the panel, as wide as the body, hides the body's side), along y the tops of body and
        panels. Defaults: (0.004, 0.06, 0.24) m^2 (agent.nav.measure area model).
        """
        s, l, w, t = self.body_side_m, self.panel_length_m, self.panel_width_m, self.panel_thickness_m
        a_x = w * t + max(0.0, s - w) * s
        a_y = s * s + 2.0 * l * t
        a_z = s * s + 2.0 * l * w
        return np.array([a_x, a_y, a_z])

    @property
    def radius_m(self) -> float:
        """Radius of the sphere about the body centre that contains the whole spacecraft."""
        return float(np.max(np.linalg.norm(self.vertices_m, axis=1)))


def _edge_table(faces: np.ndarray) -> np.ndarray:
    """Undirected edges of closed quad meshes: (a, b, face with a->b, face with b->a)."""
    directed = {}
    for fi, quad in enumerate(faces):
        for k in range(4):
            directed[(int(quad[k]), int(quad[(k + 1) % 4]))] = fi
    rows = []
    for (a, b), fl in directed.items():
        if a < b:
            rows.append((a, b, fl, directed[(b, a)]))
    return np.array(rows, dtype=np.intp)
