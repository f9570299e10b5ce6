"""A built-in, procedurally generated pair of shapes with exact ground truth.

[`example_pair`][bsfjax.example_pair] returns two poses of one smooth, closed, genus-0 "body" (torso, head, two
arms, two legs) that share their connectivity, so vertex ``i`` of the source corresponds to
vertex ``i`` of the target, together with a six-part segmentation that is the same on both.  It
needs no download and is deterministic: use it in examples, notebooks and tests.

Construction (numpy only, a few milliseconds):

1. a coarse quad *cage*: a box torso whose faces are extruded, ring after ring, into a neck and
   head, two arms and two legs (every ring is a 4-vertex square, segments are about as long as
   they are wide, so the quads stay close to square);
2. the cage is *posed*: each joint rotates the rings of its limb about the joint's rest position
   with a smooth ramp of weights over neighbouring rings (distal joints first), so limbs bend
   rather than fold and the surface is stretched only near the joints — a near-isometric,
   clearly non-rigid deformation, like two poses of a person;
3. ``levels`` rounds of Catmull–Clark subdivision turn the cage into a smooth surface with
   ``≈ 126 · 4^levels`` vertices (8066 at the default ``levels=3``), all quads, each split into
   two triangles along its shorter rest-pose diagonal.

Subdivision is linear in the cage's vertices and the same on every pose, so all poses share one
face array.  Part labels are defined on the cage faces and inherited by the faces they subdivide
into; a vertex takes the largest label among its faces, so part boundaries are the smooth curves
where limbs meet the torso.

Orientation (as FAUST and SMPL): ``+y`` is up, the body faces ``+z``, its left side is at
``+x``.  Units: the body is about 4.5 units tall.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

from .._util import BSFError
from ._mesh import Mesh

__all__ = ["ExamplePair", "example_pair", "example_mesh", "LABEL_NAMES", "JOINTS", "POSES"]

#: Part names, indexed by label.
LABEL_NAMES: tuple[str, ...] = ("torso", "head", "left_arm", "right_arm", "left_leg", "right_leg")

# Joint -> (limb label, pivot ring, weight of each ring 0, 1, 2, ...).  A ring's weight is the
# fraction of the joint's rotation it receives; ramps over two or three rings spread the bend
# (and its stretch) over more of the surface.  Ring 0 lies on the torso and never moves.
_JOINT_TABLE: dict[str, tuple[int, int, tuple[float, ...]]] = {
    "neck": (1, 1, (0.0, 0.5, 1.0, 1.0, 1.0, 1.0)),
    "left_shoulder": (2, 1, (0.0, 0.3, 0.7, 1.0, 1.0, 1.0)),
    "left_elbow": (2, 3, (0.0, 0.0, 0.0, 0.5, 1.0, 1.0)),
    "right_shoulder": (3, 1, (0.0, 0.3, 0.7, 1.0, 1.0, 1.0)),
    "right_elbow": (3, 3, (0.0, 0.0, 0.0, 0.5, 1.0, 1.0)),
    "left_hip": (4, 1, (0.0, 0.5, 1.0, 1.0, 1.0)),
    "left_knee": (4, 2, (0.0, 0.0, 0.5, 1.0, 1.0)),
    "right_hip": (5, 1, (0.0, 0.5, 1.0, 1.0, 1.0)),
    "right_knee": (5, 2, (0.0, 0.0, 0.5, 1.0, 1.0)),
}
#: Names of the joints a pose may rotate (distal joints are applied before proximal ones).
JOINTS: tuple[str, ...] = tuple(_JOINT_TABLE)

#: Built-in poses: joint -> rotation vector in degrees (axis × angle, in the rest frame).
POSES: dict[str, dict[str, tuple[float, float, float]]] = {
    # the cage as built: arms straight out sideways, legs straight down
    "rest": {},
    # relaxed "A-pose": arms 35° down, slightly bent elbows
    "source": {
        "left_shoulder": (0.0, 0.0, -35.0),
        "right_shoulder": (0.0, 0.0, 35.0),
        "left_elbow": (0.0, -10.0, 0.0),
        "right_elbow": (0.0, 10.0, 0.0),
    },
    # walking / waving: left arm raised with the forearm bent forward, right arm down, left
    # thigh lifted forward with the knee bent, right leg slightly back, head turned and tilted
    "target": {
        "left_shoulder": (0.0, 0.0, 20.0),
        "left_elbow": (0.0, -75.0, 0.0),
        "right_shoulder": (0.0, 0.0, 65.0),
        "right_elbow": (0.0, 30.0, 0.0),
        "left_hip": (-45.0, 0.0, 0.0),
        "left_knee": (65.0, 0.0, 0.0),
        "right_hip": (12.0, -5.0, 0.0),
        "right_knee": (15.0, 0.0, 0.0),
        "neck": (10.0, 35.0, 0.0),
    },
}


class ExamplePair(NamedTuple):
    """A source/target pair with exact ground truth.

    **Attributes:**

    - `source`: the source shape (``"source"`` pose).
    - `target`: the target shape (``"target"`` pose), same faces as ``source``.
    - `labels`: ``(n,)`` int64 part label of every vertex, valid on both shapes.
    - `label_names`: name of each label (``label_names[labels[i]]``).
    - `p2p`: ``(n,)`` int64 ground-truth map, ``p2p[i]`` = source vertex matched to target
      vertex ``i`` (the identity here).
    """

    source: Mesh
    target: Mesh
    labels: np.ndarray
    label_names: tuple[str, ...]
    p2p: np.ndarray


# --------------------------------------------------------------------------------------------
# cage


class _Cage:
    """A closed quad mesh under construction; faces are CCW seen from outside."""

    def __init__(self):
        self.verts: list[np.ndarray] = []
        self.faces: list[list[int]] = []
        self.face_label: list[int] = []
        self.vert_limb: list[int] = []  # -1 on the torso
        self.vert_ring: list[int] = []

    def add_vertex(self, p, limb=-1, ring=0) -> int:
        self.verts.append(np.asarray(p, dtype=np.float64))
        self.vert_limb.append(limb)
        self.vert_ring.append(ring)
        return len(self.verts) - 1

    def box(self, xs, ys, zs):
        """The surface of the grid box ``xs × ys × zs`` (1D arrays of node coordinates)."""
        coords = (np.asarray(xs), np.asarray(ys), np.asarray(zs))
        sizes = [len(c) - 1 for c in coords]
        index: dict[tuple[int, int, int], int] = {}

        def vid(ijk):
            if ijk not in index:
                index[ijk] = self.add_vertex([coords[a][ijk[a]] for a in range(3)])
            return index[ijk]

        for a in range(3):
            u, v = (a + 1) % 3, (a + 2) % 3  # e_u × e_v = e_a
            for side in (0, sizes[a]):
                for i in range(sizes[u]):
                    for j in range(sizes[v]):
                        corners = []
                        for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1)):
                            ijk = [0, 0, 0]
                            ijk[a], ijk[u], ijk[v] = side, i + di, j + dj
                            corners.append(vid(tuple(ijk)))
                        if side == 0:
                            corners = corners[::-1]
                        self.faces.append(corners)
                        self.face_label.append(0)
        return index

    def find_face(self, centre) -> int:
        c = np.asarray(self.verts)[np.asarray(self.faces)].mean(axis=1)
        return int(np.argmin(np.linalg.norm(c - np.asarray(centre), axis=1)))

    def extrude_chain(self, face: int, label: int, steps) -> None:
        """Extrude ``face`` repeatedly; ``steps`` = ``(length, scale)`` per new ring.

        Each step moves a copy of the face ``length`` along its normal and scales it about its
        centre by ``scale``; the face is replaced by the copy and four side quads join the rings.
        """
        for ring, (length, scale) in enumerate(steps, start=1):
            ids = self.faces[face]
            p = np.asarray([self.verts[i] for i in ids])
            c = p.mean(axis=0)
            nrm = np.cross(p[1] - p[0], p[3] - p[0]) + np.cross(p[3] - p[2], p[1] - p[2])
            nrm /= np.linalg.norm(nrm)
            new = [self.add_vertex(c + scale * (q - c) + length * nrm, label, ring) for q in p]
            for k in range(4):  # side quad (p, q, q', p') has outward normal (q − p) × n
                a, b = ids[k], ids[(k + 1) % 4]
                self.faces.append([a, b, new[(k + 1) % 4], new[k]])
                self.face_label.append(label)
            self.faces[face] = new
            self.face_label[face] = label


def _build_cage():
    """The rest-pose cage: vertices (V, 3), quads (F, 4), face labels, vertex limb and ring."""
    cage = _Cage()
    w, d = 0.4, 0.6  # torso grid spacing in x (and z), depth in y
    xs = np.array([-1.5, -0.5, 0.5, 1.5]) * w
    cage.box(xs, [-d / 2, d / 2], np.arange(5) * w)
    # taper the torso: a waist, broader shoulders and chest (a pure x-scale per height)
    v = np.asarray(cage.verts)
    width = np.interp(v[:, 2], np.arange(5) * w, [1.0, 0.88, 0.84, 0.95, 1.0])
    for i in range(len(cage.verts)):
        cage.verts[i] = v[i] * np.array([width[i], 1.0, 1.0])
    top, bottom = 4 * w, 0.0
    # head: short narrow neck, widening into a head, closed by a smaller cap
    cage.extrude_chain(cage.find_face([0, 0, top]), 1,
                       [(0.2, 0.7), (0.18, 1.9), (0.42, 1.0), (0.2, 0.55)])
    # arms from the upper side faces: shoulder, upper arm, elbow, wrist, hand
    arm = [(0.25, 0.82), (0.42, 0.95), (0.42, 0.92), (0.48, 0.85), (0.36, 1.0)]
    cage.extrude_chain(cage.find_face([1.5 * w, 0, 3.5 * w]), 2, arm)
    cage.extrude_chain(cage.find_face([-1.5 * w, 0, 3.5 * w]), 3, arm)
    # legs from the outer bottom faces: hip, knee, shin, ankle
    leg = [(0.3, 0.95), (0.62, 0.93), (0.52, 0.9), (0.55, 0.85)]
    cage.extrude_chain(cage.find_face([w, 0, bottom]), 4, leg)
    cage.extrude_chain(cage.find_face([-w, 0, bottom]), 5, leg)
    # built z-up facing −y; output y-up facing +z (the FAUST / SMPL convention): a rotation
    verts = np.asarray(cage.verts) @ np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]).T
    return (verts, np.asarray(cage.faces, dtype=np.int64),
            np.asarray(cage.face_label, dtype=np.int64), np.asarray(cage.vert_limb),
            np.asarray(cage.vert_ring))


def _rotation(rotvec: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation matrices (..., 3, 3) from rotation vectors (..., 3) in radians."""
    theta = np.linalg.norm(rotvec, axis=-1)[..., None, None]
    k = rotvec / np.maximum(theta[..., 0], 1e-300)
    K = np.zeros(rotvec.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    K = K - np.swapaxes(K, -1, -2)
    return np.eye(3) + np.sin(theta) * K + (1.0 - np.cos(theta)) * (K @ K)


def _pose_cage(verts, limb, ring, pose: Mapping[str, tuple[float, float, float]]) -> np.ndarray:
    """Rotate limb rings about rest-pose joint centres, distal joints first."""
    out = verts.copy()
    # proximal joints come first in _JOINT_TABLE's per-limb order; apply in reverse
    for name in reversed(JOINTS):
        if name not in pose:
            continue
        lab, pivot_ring, weights = _JOINT_TABLE[name]
        rv = np.deg2rad(np.asarray(pose[name], dtype=np.float64))
        on_limb = limb == lab
        pivot = verts[on_limb & (ring == pivot_ring)].mean(axis=0)
        wts = np.zeros(len(verts))
        wts[on_limb] = np.asarray(weights)[ring[on_limb]]
        moving = wts > 0
        R = _rotation(wts[moving, None] * rv)  # per-vertex fraction of the joint's rotation
        out[moving] = pivot + np.einsum("nij,nj->ni", R, out[moving] - pivot)
    return out


def _validate_pose(pose, arg: str = "pose") -> dict[str, tuple[float, float, float]]:
    if isinstance(pose, str):
        if pose not in POSES:
            raise BSFError(f"{arg} must be one of {sorted(POSES)} or a mapping joint -> rotation "
                           f"vector in degrees, got {pose!r}")
        return POSES[pose]
    if not isinstance(pose, Mapping):
        raise BSFError(f"{arg} must be a pose name or a mapping, got {type(pose).__name__}")
    out = {}
    for name, rv in pose.items():
        if name not in _JOINT_TABLE:
            raise BSFError(f"{arg}: unknown joint {name!r}; joints are {list(JOINTS)}")
        try:
            arr = np.asarray(rv, dtype=np.float64)
        except (TypeError, ValueError):
            arr = np.full(0, np.nan)
        if arr.shape != (3,) or not np.all(np.isfinite(arr)):
            raise BSFError(f"{arg}[{name!r}] must be 3 finite numbers (a rotation vector in "
                           f"degrees), got {rv!r}")
        out[name] = tuple(float(x) for x in arr)
    return out


# --------------------------------------------------------------------------------------------
# Catmull–Clark subdivision of a closed quad mesh


def _catmull_clark_topology(faces: np.ndarray, n: int):
    """Connectivity of one Catmull–Clark step: edges, the new quads, the face of each quad."""
    m = faces.shape[0]
    he = np.stack([faces, np.roll(faces, -1, axis=1)], axis=-1).reshape(-1, 2)  # (4m, 2)
    key = np.minimum(he[:, 0], he[:, 1]) * n + np.maximum(he[:, 0], he[:, 1])
    uniq, he_edge = np.unique(key, return_inverse=True)
    edges = np.stack([uniq // n, uniq % n], axis=1)
    e = he_edge.reshape(m, 4)  # e[f, i] = edge (faces[f, i], faces[f, i + 1])
    ne = edges.shape[0]
    fidx = n + ne + np.arange(m)
    # corner i of face f -> quad (v_i, edge(i, i+1), face point, edge(i-1, i)); CCW preserved
    quads = np.stack([faces, n + e, np.broadcast_to(fidx[:, None], (m, 4)),
                      n + np.roll(e, 1, axis=1)], axis=-1).reshape(-1, 4)
    return edges, he_edge, quads


def _catmull_clark_points(verts, faces, edges, he_edge) -> np.ndarray:
    n, m = verts.shape[0], faces.shape[0]
    fp = verts[faces].mean(axis=1)
    he_face = np.repeat(np.arange(m), 4)
    ne = edges.shape[0]

    def scatter(idx, vals, size):
        return np.stack([np.bincount(idx, vals[:, c], minlength=size) for c in range(3)], axis=1)

    # closed mesh: every edge has exactly two faces
    ep = (verts[edges[:, 0]] + verts[edges[:, 1]] + scatter(he_edge, fp[he_face], ne)) / 4.0
    val = np.bincount(faces.ravel(), minlength=n).astype(np.float64)[:, None]
    Q = scatter(faces.ravel(), np.repeat(fp, 4, axis=0), n) / val  # mean adjacent face point
    mid = 0.5 * (verts[edges[:, 0]] + verts[edges[:, 1]])
    R = scatter(edges.ravel(), np.repeat(mid, 2, axis=0), n) / val  # mean incident edge midpoint
    vp = (Q + 2.0 * R + (val - 3.0) * verts) / val
    return np.concatenate([vp, ep, fp], axis=0)


def _subdivide(poses: list[np.ndarray], faces: np.ndarray, face_label: np.ndarray, levels: int):
    for _ in range(levels):
        n = poses[0].shape[0]
        edges, he_edge, quads = _catmull_clark_topology(faces, n)
        poses = [_catmull_clark_points(v, faces, edges, he_edge) for v in poses]
        face_label = np.repeat(face_label, 4)
        faces = quads
    return poses, faces, face_label


def _triangulate_quads(rest: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Split each quad along its shorter diagonal in ``rest`` (same split for every pose)."""
    d02 = np.linalg.norm(rest[quads[:, 0]] - rest[quads[:, 2]], axis=1)
    d13 = np.linalg.norm(rest[quads[:, 1]] - rest[quads[:, 3]], axis=1)
    a, b, c, d = quads.T
    use02 = (d02 <= d13)[:, None]
    t1 = np.where(use02, np.stack([a, b, c], 1), np.stack([a, b, d], 1))
    t2 = np.where(use02, np.stack([a, c, d], 1), np.stack([b, c, d], 1))
    return np.concatenate([t1, t2], axis=0)


def _check_levels(levels) -> int:
    ok = isinstance(levels, (int, np.integer)) and not isinstance(levels, bool)
    if not ok or not 1 <= levels <= 5:
        raise BSFError(f"levels must be an integer in [1, 5] (vertices ≈ 126·4^levels), "
                       f"got {levels!r}")
    return int(levels)


def _build(poses: list, levels: int):
    levels = _check_levels(levels)
    cage_v, cage_f, cage_lab, limb, ring = _build_cage()
    posed = [_pose_cage(cage_v, limb, ring, p) for p in poses]
    (rest, *posed), quads, qlab = _subdivide([cage_v, *posed], cage_f, cage_lab, levels)
    tris = _triangulate_quads(rest, quads)
    n = rest.shape[0]
    # vertex label = largest label among its faces: rings where a limb meets the torso go to the
    # limb, so each part's vertex set is connected
    labels = np.zeros(n, dtype=np.int64)
    np.maximum.at(labels, quads.ravel(), np.repeat(qlab, 4))
    return posed, tris, labels


def example_mesh(pose: str | Mapping[str, tuple[float, float, float]] = "source",
                 levels: int = 3) -> Mesh:
    """One pose of the built-in body.

    **Arguments:**

    - `pose`: ``"rest"`` (arms out sideways), ``"source"`` or ``"target"`` (see `POSES`),
      or a mapping joint name (`JOINTS`) -> rotation vector ``(rx, ry, rz)`` in
      degrees in the rest frame (axis × angle; joints not given stay straight).  Every
      pose has the same faces, so any two are in vertex-to-vertex correspondence.
    - `levels`: Catmull–Clark levels; the mesh has ``126 · 4^levels + 2`` vertices
      (``levels=2``: 2018, ``3``: 8066, ``4``: 32258).

    **Returns:**

    A closed, genus-0 triangle [`Mesh`][bsfjax.Mesh] named ``"example:<pose>"``.
    """
    p = _validate_pose(pose)
    (v,), tris, _ = _build([p], levels)
    return Mesh(v, tris, name=f"example:{pose if isinstance(pose, str) else 'custom'}")


def example_pair(levels: int = 3, *, source_pose="source", target_pose="target") -> ExamplePair:
    """A source/target pair of body shapes in different poses, with exact ground truth.

    **Arguments:**

    - `levels`: Catmull–Clark levels (size: ``126 · 4^levels + 2`` vertices; default 8066).
    - `source_pose`, `target_pose`: poses as in [`example_mesh`][bsfjax.example_mesh].

    **Returns:**

    [`ExamplePair`][bsfjax.ExamplePair] with the two meshes (identical faces), the six-part segmentation
    ``labels`` (``label_names`` = `LABEL_NAMES`) and ``p2p = arange(n)``.

    The deformation is near-isometric (edge lengths change only near the bent joints) yet far
    from rigid.  Deterministic; builds in a few tens of milliseconds.
    """
    ps, pt = _validate_pose(source_pose, "source_pose"), _validate_pose(target_pose, "target_pose")
    (vs, vt), tris, labels = _build([ps, pt], levels)
    n = vs.shape[0]
    src = Mesh(vs, tris, name="example:source")
    tgt = Mesh(vt, tris, name="example:target")
    labels.setflags(write=False)
    p2p = np.arange(n, dtype=np.int64)
    p2p.setflags(write=False)
    return ExamplePair(src, tgt, labels, LABEL_NAMES, p2p)
