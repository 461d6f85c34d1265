"""A 2D pose graph: keyframe poses joined by relative-pose constraints, optimised by sparse least squares.

Nodes are keyframe poses (x m, y m, yaw rad) in the map frame; an edge
``(i, j, z, information)`` says that node ``j`` seen from node ``i`` sits at
``z = (dx, dy, dyaw)`` (in ``i``'s frame), with ``information`` the inverse of
its 3x3 covariance. Odometry, scan matches and loop closures are all edges.
The optimiser minimises ``sum_e r_e^T I_e r_e`` with ``r_e = z^-1 (x_i^-1 x_j)``
as a (dx, dy, wrapped dyaw) error, node 0 held fixed (it defines the map frame),
with SciPy's ``least_squares`` (trust region reflective) on the sparse
Jacobian: each edge's three residuals depend on six unknowns, which is what
``jac_sparsity`` tells it, so a graph of hundreds of nodes solves in tens of
milliseconds. A robust loss (``soft_l1``, scaled at 3 sigma) keeps one wrong
loop closure from bending the whole map.

SciPy rather than GTSAM: SciPy is already a dependency (no extra wheel on a
Raspberry Pi), and at the sizes a room-to-floor map reaches (hundreds of
keyframes) its solve is a few tens of milliseconds, done only on a loop
closure and at the end (see docs/mapping.md for the figures).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from beastbt.mapping.scan_matcher import Pose2, wrap


def relative(a: Pose2, b: Pose2) -> Pose2:
    """Pose ``b`` seen from pose ``a`` (both in one frame): ``a^-1 b`` (m, m, rad)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return (c * dx + s * dy, -s * dx + c * dy, wrap(b[2] - a[2]))


def compose(a: Pose2, d: Pose2) -> Pose2:
    """Pose ``d`` (given in ``a``'s frame) in ``a``'s own frame: ``a d`` (m, m, rad)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * d[0] - s * d[1], a[1] + s * d[0] + c * d[1], wrap(a[2] + d[2]))


@dataclass(frozen=True)
class Edge:
    """A constraint: node ``j`` seen from node ``i`` is at ``z`` (m, m, rad) with ``information`` (3x3, the
    inverse covariance); ``kind`` says where it came from (``odometry``, ``scan``, ``loop``)."""

    i: int
    j: int
    z: Pose2
    information: np.ndarray
    kind: str = "scan"


@dataclass
class PoseGraph:
    """Keyframe poses and the edges between them; :meth:`optimise` moves the poses to fit the edges best."""

    poses: list[Pose2] = field(default_factory=list)
    edges: list[Edge] = field(default_factory=list)

    def add_node(self, pose: Pose2) -> int:
        """Add a keyframe at ``pose`` (the current estimate); its index."""
        self.poses.append((float(pose[0]), float(pose[1]), float(pose[2])))
        return len(self.poses) - 1

    def add_edge(self, i: int, j: int, z: Pose2, covariance: np.ndarray, kind: str = "scan") -> None:
        """Add the constraint "node ``j`` is at ``z`` from node ``i``" with its 3x3 ``covariance``."""
        cov = np.asarray(covariance, dtype=float) + np.eye(3) * 1e-9
        self.edges.append(Edge(i, j, (float(z[0]), float(z[1]), float(z[2])), np.linalg.inv(cov), kind))

    def _arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The edges' node indices and measurements as arrays (i, j, z)."""
        return (np.array([e.i for e in self.edges]), np.array([e.j for e in self.edges]),
                np.array([e.z for e in self.edges]).reshape(-1, 3))

    def residuals(self, poses: np.ndarray) -> np.ndarray:
        """The whitened errors of every edge (3 per edge) for ``poses`` (n, 3)."""
        if not self.edges:
            return np.zeros(0)
        i, j, z = self._arrays()
        return self._residuals(poses, i, j, z)

    def _residuals(self, poses: np.ndarray, i: np.ndarray, j: np.ndarray, z: np.ndarray) -> np.ndarray:
        xi, xj = poses[i], poses[j]
        c, s = np.cos(xi[:, 2]), np.sin(xi[:, 2])
        dx, dy = xj[:, 0] - xi[:, 0], xj[:, 1] - xi[:, 1]
        rel = np.column_stack((c * dx + s * dy, -s * dx + c * dy, xj[:, 2] - xi[:, 2]))
        # The error in the measurement's frame: z^-1 rel.
        cz, sz = np.cos(z[:, 2]), np.sin(z[:, 2])
        ex, ey = rel[:, 0] - z[:, 0], rel[:, 1] - z[:, 1]
        err = np.column_stack((cz * ex + sz * ey, -sz * ex + cz * ey,
                               (rel[:, 2] - z[:, 2] + np.pi) % (2 * np.pi) - np.pi))
        return np.einsum("eab,eb->ea", self._sqrt_info(), err).ravel()

    def _jacobian(self, poses: np.ndarray, i: np.ndarray, j: np.ndarray, z: np.ndarray) -> Any:
        """The whitened residuals' Jacobian (3 m x 3 (n - 1), sparse): each edge depends on its two nodes only."""
        from scipy.sparse import csr_matrix

        m, n = len(i), len(poses)
        xi, xj = poses[i], poses[j]
        c, s = np.cos(xi[:, 2]), np.sin(xi[:, 2])
        dx, dy = xj[:, 0] - xi[:, 0], xj[:, 1] - xi[:, 1]
        cz, sz = np.cos(z[:, 2]), np.sin(z[:, 2])
        rz = np.zeros((m, 3, 3))  # the measurement's rotation, transposed, on (x, y); 1 on yaw
        rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1], rz[:, 2, 2] = cz, sz, -sz, cz, 1.0
        ji = np.zeros((m, 3, 3))  # d(rel)/d(x_i)
        ji[:, 0, 0], ji[:, 0, 1], ji[:, 0, 2] = -c, -s, -s * dx + c * dy
        ji[:, 1, 0], ji[:, 1, 1], ji[:, 1, 2] = s, -c, -c * dx - s * dy
        ji[:, 2, 2] = -1.0
        jj = np.zeros((m, 3, 3))  # d(rel)/d(x_j)
        jj[:, 0, 0], jj[:, 0, 1], jj[:, 1, 0], jj[:, 1, 1], jj[:, 2, 2] = c, s, -s, c, 1.0
        w = np.einsum("eab,ebc->eac", self._sqrt_info(), rz)
        blocks = (np.einsum("eab,ebc->eac", w, ji), np.einsum("eab,ebc->eac", w, jj))
        rows, cols, data = [], [], []
        r = 3 * np.arange(m)[:, None, None] + np.arange(3)[None, :, None] + np.zeros((1, 1, 3), dtype=np.int64)
        for node, block in zip((i, j), blocks):
            keep = node > 0  # node 0 is held fixed: no column
            col = 3 * (node[:, None, None] - 1) + np.arange(3)[None, None, :] + np.zeros((1, 3, 1), dtype=np.int64)
            rows.append(r[keep].ravel())
            cols.append(col[keep].ravel())
            data.append(block[keep].ravel())
        return csr_matrix((np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(3 * m, 3 * (n - 1)))

    def _sqrt_info(self) -> np.ndarray:
        """The edges' square-root information (upper Cholesky factors), cached while no edge is added."""
        cached = getattr(self, "_sqrt_cache", None)
        if cached is not None and cached[0] == len(self.edges):
            return cached[1]
        roots = np.array([np.linalg.cholesky(e.information).T for e in self.edges])
        self._sqrt_cache = (len(self.edges), roots)
        return roots

    def optimise(self, max_evaluations: int = 50) -> float:
        """Move every pose but node 0 to minimise the edges' errors; the final cost (sum of squared whitened
        errors, unitless). With fewer than two nodes or no edges it does nothing."""
        from scipy.optimize import least_squares

        n = len(self.poses)
        if n < 2 or not self.edges:
            return 0.0
        x0 = np.array(self.poses, dtype=float)
        anchor = x0[0].copy()
        i, j, z = self._arrays()

        def full(v: np.ndarray) -> np.ndarray:
            return np.vstack((anchor, v.reshape(n - 1, 3)))

        result = least_squares(lambda v: self._residuals(full(v), i, j, z), x0[1:].ravel(),
                               jac=lambda v: self._jacobian(full(v), i, j, z), method="trf", loss="soft_l1",
                               f_scale=3.0, x_scale="jac", max_nfev=max_evaluations, tr_solver="lsmr")
        solved = result.x.reshape(n - 1, 3)
        solved[:, 2] = (solved[:, 2] + np.pi) % (2 * np.pi) - np.pi
        self.poses = [self.poses[0]] + [tuple(map(float, p)) for p in solved]  # type: ignore[misc]
        return float(2.0 * result.cost)


def chain_covariance(distance_m: float, turned_rad: float, sigma_xy_per_m: float = 0.1,
                     sigma_yaw_per_rad: float = 0.1, sigma_yaw_per_m: float = 0.1) -> np.ndarray:
    """The covariance (m^2, rad^2) of an odometry step: errors that grow with the distance driven and the angle
    turned (wheel slip), with small floors so a standstill is not infinitely sure."""
    sxy = max(0.005, sigma_xy_per_m * distance_m)
    syaw = max(math.radians(0.2), sigma_yaw_per_rad * abs(turned_rad) + sigma_yaw_per_m * distance_m)
    return np.diag((sxy ** 2, sxy ** 2, syaw ** 2))


def poses_array(poses: Sequence[Pose2]) -> np.ndarray:
    """Poses as an (n, 3) array."""
    return np.array(poses, dtype=float).reshape(-1, 3)


__all__ = ["PoseGraph", "Edge", "relative", "compose", "chain_covariance", "poses_array"]
