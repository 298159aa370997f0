"""An algorithm's final trajectory at every scan from its key poses (graph SLAM's optimised
nodes, a particle filter's best particle at each update): vectorised SE(2) helpers, the blend
of the odometry between two key poses, and a particle filter's lineage.
"""

from __future__ import annotations

import math

import numpy as np


def relative_many(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, 3) inv(a_k) (+) b_k for (N, 3) poses [x, y, theta]."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    dth = (b[:, 2] - a[:, 2] + math.pi) % (2.0 * math.pi) - math.pi
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy, dth])


def compose_many(a: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(N, 3) a_k (+) d_k."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    th = (a[:, 2] + d[:, 2] + math.pi) % (2.0 * math.pi) - math.pi
    return np.column_stack(
        [a[:, 0] + c * d[:, 0] - s * d[:, 1], a[:, 1] + s * d[:, 0] + c * d[:, 1], th]
    )


def between_keys(
    key_pose: np.ndarray,
    key_odom: np.ndarray,
    key_path: np.ndarray,
    scan_odom: np.ndarray,
    scan_key: np.ndarray,
    scan_path: np.ndarray,
) -> np.ndarray:
    """(N, 3) the pose at every scan from K key poses.

    key_pose (K, 3): the final poses (map frame) of the key scans; key_odom (K, 3) their
    odometry; key_path (K,) [m] the odometry path length at each. scan_odom (N, 3), scan_path
    (N,): the same of every scan; scan_key (N,) the latest key at or before each scan (-1:
    none yet, the scan keeps its odometry). A key scan is at its key pose; a scan between keys
    a and b at the two poses the odometry gives from each, (P_a (+) o_a^-1 o_s) and
    (P_b (+) o_b^-1 o_s), blended by the share of the odometry path from a to b travelled at
    the scan; scans after the last key from it alone.
    """
    out = np.array(scan_odom, dtype=np.float64).reshape(-1, 3)
    has = scan_key >= 0
    if not has.any():
        return out
    a = scan_key[has]
    fwd = compose_many(key_pose[a], relative_many(key_odom[a], out[has]))
    b = np.minimum(a + 1, key_pose.shape[0] - 1)
    bwd = compose_many(key_pose[b], relative_many(key_odom[b], out[has]))
    span = key_path[b] - key_path[a]
    along = scan_path[has] - key_path[a]
    w = np.clip(along / np.where(span > 0, span, np.inf), 0.0, 1.0)
    d = bwd - fwd
    d[:, 2] = (d[:, 2] + math.pi) % (2.0 * math.pi) - math.pi
    blend = fwd + w[:, None] * d
    blend[:, 2] = (blend[:, 2] + math.pi) % (2.0 * math.pi) - math.pi
    out[has] = blend
    return out


class ScanTrack:
    """Per scan processed: its odometry pose, the odometry path length so far [m], and the
    latest key (node, update) at or before it (-1: none yet): what `between_keys` needs."""

    def __init__(self) -> None:
        self.path_m = 0.0  # [m] odometry path length at the latest scan
        self._odom: list[np.ndarray] = []
        self._path: list[float] = []
        self._key: list[int] = []

    def scan(self, pose_odom: np.ndarray) -> None:
        """Note a scan (its key stays the latest one unless `keyed` follows)."""
        if self._odom:
            last = self._odom[-1]
            self.path_m += math.hypot(pose_odom[0] - last[0], pose_odom[1] - last[1])
        self._odom.append(np.array(pose_odom, dtype=np.float64))
        self._path.append(self.path_m)
        self._key.append(self._key[-1] if self._key else -1)

    def keyed(self, key: int) -> None:
        """The latest scan is key `key`."""
        self._key[-1] = key

    @property
    def odom(self) -> np.ndarray:
        """(3,) the latest scan's odometry pose."""
        return self._odom[-1]

    def trajectory(self, key_pose: np.ndarray, key_odom: np.ndarray, key_path: np.ndarray):
        """(N, 3) every scan's pose from the keys' (see between_keys)."""
        if not self._odom:
            return np.zeros((0, 3))
        return between_keys(
            key_pose, key_odom, key_path, np.array(self._odom),
            np.array(self._key, dtype=np.int64), np.array(self._path),
        )  # fmt: skip


class Lineage:
    """A particle filter's history: each particle's pose at every update and which particle of
    the update before it descends from, so that one particle's whole path can be read back
    (GMapping's trajectory tree, TNode: the best particle's path is its final trajectory, the
    one its final map was built along). 8 * N * 4 bytes an update (N particles)."""

    def __init__(self) -> None:
        self._poses: list[np.ndarray] = []  # per update: (N, 3) poses after it
        self._parents: list[np.ndarray | None] = []  # per update: (N,) index into the one before
        self._odom: list[np.ndarray] = []  # per update: (3,) the raw odometry at it
        self._path: list[float] = []  # per update: [m] odometry path length at it
        self._scans = ScanTrack()

    def scan(self, pose_odom: np.ndarray) -> None:
        """Note a scan's raw odometry (before `update`, when the scan is one)."""
        self._scans.scan(pose_odom)

    def update(self, poses: np.ndarray, parents: np.ndarray | None) -> None:
        """Note the update of the latest scan: the particles' poses after it, and for each
        the particle of the previous update it descends from (None: the same index)."""
        self._poses.append(np.array(poses, dtype=np.float64))
        self._parents.append(None if parents is None else np.asarray(parents, dtype=np.int64))
        self._odom.append(self._scans.odom)
        self._path.append(self._scans.path_m)
        self._scans.keyed(len(self._poses) - 1)

    def path(self, particle: int) -> np.ndarray:
        """(K, 3) the poses of `particle` (an index into the latest update) and its ancestors
        at every update."""
        k = len(self._poses)
        out = np.empty((k, 3))
        i = int(particle)
        for u in range(k - 1, -1, -1):
            out[u] = self._poses[u][i]
            parents = self._parents[u]
            if parents is not None:
                i = int(parents[i])
        return out

    def trajectory(self, particle: int) -> np.ndarray:
        """(N, 3) the pose at every scan noted, along `particle`'s path (see between_keys)."""
        return self._scans.trajectory(
            self.path(particle), np.array(self._odom).reshape(-1, 3), np.array(self._path)
        )
