"""Constant-velocity Kalman filter on image boxes (Deep SORT's, after Wojke et al. 2017).

State: (x, y, a, h, vx, vy, va, vh): box centre (px), aspect ratio w/h, height (px) and their
velocities per frame. Measurement: (x, y, a, h). Noise scales with the box height, so a far
(small) fruit is held to tighter pixel bounds than a near (large) one.
"""

from __future__ import annotations

import numpy as np

CHI2INV95 = {1: 3.8415, 2: 5.9915, 3: 7.8147, 4: 9.4877, 5: 11.070, 6: 12.592, 7: 14.067, 8: 15.507}
"""0.95 quantile of the chi-square distribution by degrees of freedom: the Mahalanobis gate."""


def xyxy_to_xyah(box: np.ndarray) -> np.ndarray:
    """(x1, y1, x2, y2) → (cx, cy, w/h, h); works on (4,) and (N, 4)."""
    b = np.asarray(box, dtype=np.float64)
    w = b[..., 2] - b[..., 0]
    h = np.maximum(b[..., 3] - b[..., 1], 1e-6)
    return np.stack([b[..., 0] + w / 2, b[..., 1] + h / 2, w / h, h], axis=-1)


def xyah_to_xyxy(xyah: np.ndarray) -> np.ndarray:
    a = np.asarray(xyah, dtype=np.float64)
    w = a[..., 2] * a[..., 3]
    half = np.stack([w / 2, a[..., 3] / 2], axis=-1)
    return np.concatenate([a[..., :2] - half, a[..., :2] + half], axis=-1)


class KalmanFilter:
    """Deep SORT's filter with its noise weights (1/20 of the height for position, 1/160 for
    velocity per frame)."""

    def __init__(
        self, std_weight_position: float = 1.0 / 20, std_weight_velocity: float = 1.0 / 160
    ) -> None:
        ndim, dt = 4, 1.0
        self._F = np.eye(2 * ndim)
        for i in range(ndim):
            self._F[i, ndim + i] = dt
        self._H = np.eye(ndim, 2 * ndim)
        self._wp = std_weight_position
        self._wv = std_weight_velocity

    def initiate(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and covariance of a new track from its first measurement (velocity 0)."""
        mean = np.r_[z, np.zeros(4)]
        h = z[3]
        std = [
            2 * self._wp * h,
            2 * self._wp * h,
            1e-2,
            2 * self._wp * h,
            10 * self._wv * h,
            10 * self._wv * h,
            1e-5,
            10 * self._wv * h,
        ]
        return mean, np.diag(np.square(std))

    def predict(self, mean: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        means, covs = self.predict_many(mean[None], cov[None])
        return means[0], covs[0]

    def predict_many(self, means: np.ndarray, covs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """T tracks one frame ahead at once: (T, 8) means, (T, 8, 8) covariances. Batched
        because 30 tracks' worth of tiny per-track numpy calls cost more than the arithmetic;
        every entry of F P F^T sums two terms, so the result is the per-track one to the bit."""
        h = means[:, 3]
        wp, wv = self._wp * h, self._wv * h
        q = np.square(
            np.stack([wp, wp, np.full_like(h, 1e-2), wp, wv, wv, np.full_like(h, 1e-5), wv], 1)
        )
        out = self._F @ covs @ self._F.T
        out[:, np.arange(8), np.arange(8)] += q
        return means @ self._F.T, out

    def update(
        self, mean: np.ndarray, cov: np.ndarray, z: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        means, covs = self.update_many(mean[None], cov[None], np.asarray(z, float)[None])
        return means[0], covs[0]

    def update_many(
        self, means: np.ndarray, covs: np.ndarray, zs: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """M tracks corrected by their measurements (M, 4) at once (H selects the first four
        state entries, so H P H^T and P H^T are slices)."""
        h = means[:, 3]
        r = np.square(
            np.stack([self._wp * h, self._wp * h, np.full_like(h, 1e-1), self._wp * h], 1)
        )
        pc = covs[:, :4, :4].copy()
        pc[:, np.arange(4), np.arange(4)] += r
        # 4x4 systems: numpy's batched solve is exact enough and far cheaper than per-call
        # wrappers, which matters with 30 tracks at 15 Hz.
        gain = np.linalg.solve(pc, covs[:, :, :4].transpose(0, 2, 1)).transpose(0, 2, 1)
        innovation = zs - means[:, :4]
        new_means = means + np.einsum("mij,mj->mi", gain, innovation)
        new_covs = covs - gain @ pc @ gain.transpose(0, 2, 1)
        return new_means, new_covs

    def gating_distance(self, mean: np.ndarray, cov: np.ndarray, zs: np.ndarray) -> np.ndarray:
        """Squared Mahalanobis distance of each measurement (N, 4) to the predicted box."""
        return self.gating_distances(mean[None], cov[None], zs)[0]

    def gating_distances(self, means: np.ndarray, covs: np.ndarray, zs: np.ndarray) -> np.ndarray:
        """(T, N) squared Mahalanobis distances of N measurements to T tracks, in one batch."""
        h = means[:, 3]
        pm = means[:, :4]
        pc = covs[:, :4, :4].copy()
        r = np.square(
            np.stack([self._wp * h, self._wp * h, np.full_like(h, 1e-1), self._wp * h], 1)
        )
        pc[:, np.arange(4), np.arange(4)] += r
        d = zs[None, :, :] - pm[:, None, :]  # (T, N, 4)
        x = np.linalg.solve(pc, d.transpose(0, 2, 1))  # (T, 4, N)
        return np.einsum("tnk,tkn->tn", d, x)
