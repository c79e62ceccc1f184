"""The paper's Extended Kalman Filter, batched over replicates.

State ``x = [posX, velX, posY, velY, posZ, velZ]`` (NED) [m, m/s] with the
constant-velocity transition ``Φ = blockdiag([[1, Δt], [0, 1]] × 3)`` and
white-noise-acceleration process noise
``Q = q · [[Δt³/3, Δt²/2], [Δt²/2, Δt]]`` per axis (q_h for North and East,
q_v for Down) [m²/s³]. Measurements: the latest range of each beacon and the
depth, ``z = [r_1 … r_n, d]``, with ``h_i(x) = ‖p − b̃_i‖`` (casadi Jacobian)
and the depth row ``[0 0 0 0 1 0]``; ``R = diag(σ_r², …, σ_r², σ_d²)``. A
missing measurement (a beacon never heard) gets a zero Jacobian row and a zero
innovation, which leaves the update exact for the others. The covariance
update uses the Joseph form.

References
----------
Cario et al., Sensors 21(3):762, 2021, doi:10.3390/s21030762, Section 4.3.
Bar-Shalom, Li, Kirubarajan, Estimation with Applications to Tracking and
Navigation, Wiley 2001, Sections 5.2 (Joseph form), 6.2 (white-noise
acceleration model), 5.4 (NIS).
"""

from __future__ import annotations

import numpy as np

from models.receiver.jacobian import STATE_SIZE, range_and_jacobian

DEPTH_ROW = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 0.0])


def transition(dt: float) -> np.ndarray:
    """Constant-velocity transition matrix Φ, shape (6, 6), for a step ``dt`` [s]."""
    phi = np.eye(STATE_SIZE)
    phi[0, 1] = phi[2, 3] = phi[4, 5] = dt
    return phi


def process_noise(dt: float, q_horizontal, q_vertical) -> np.ndarray:
    """White-noise-acceleration process noise Q [m², m²/s, m²/s²].

    Returns shape (6, 6) for scalar densities [m²/s³], or (B, 6, 6) when
    they are arrays of shape (B,).
    """
    block = np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    q_h, q_v = np.broadcast_arrays(np.asarray(q_horizontal, dtype=float), np.asarray(q_vertical, dtype=float))
    q = np.zeros(q_h.shape + (STATE_SIZE, STATE_SIZE))
    for axis, density in enumerate((q_h, q_h, q_v)):
        q[..., 2 * axis:2 * axis + 2, 2 * axis:2 * axis + 2] = density[..., None, None] * block
    return q


class ExtendedKalmanFilter:
    """Batched EKF of the diver's position and velocity.

    Parameters
    ----------
    x0 : ndarray, shape (B, 6)
        Initial state [m, m/s].
    P0 : ndarray, shape (6, 6) or (B, 6, 6)
        Initial covariance, shared or per replicate.
    q_horizontal, q_vertical : float or ndarray, shape (B,)
        Acceleration noise spectral densities [m²/s³].
    sigma_range, sigma_depth : float or ndarray, shape (B,)
        Measurement standard deviations in R [m].

    Attributes
    ----------
    x : ndarray, shape (B, 6)
        State estimate.
    P : ndarray, shape (B, 6, 6)
        State covariance.
    y : ndarray, shape (B, n + 1)
        Innovation of the last update (0 for missing measurements) [m].
    S : ndarray, shape (B, n + 1, n + 1)
        Innovation covariance of the last update [m²].
    nis : ndarray, shape (B,)
        Normalized innovation squared ``yᵀ S⁻¹ y`` of the last update.
    """

    def __init__(self, x0: np.ndarray, P0: np.ndarray, q_horizontal, q_vertical,
                 sigma_range, sigma_depth) -> None:
        self.x = np.array(x0, dtype=float)
        batch = self.x.shape[0]
        self.P = np.broadcast_to(P0, (batch, STATE_SIZE, STATE_SIZE)).copy()
        self.q_horizontal, self.q_vertical = q_horizontal, q_vertical
        self.sigma_range = np.broadcast_to(np.asarray(sigma_range, dtype=float), (batch,))
        self.sigma_depth = np.broadcast_to(np.asarray(sigma_depth, dtype=float), (batch,))
        self.nis = np.full(batch, np.nan)

    def predict(self, dt: float) -> None:
        """Propagate state and covariance by ``dt`` [s]: ``x ← Φx``, ``P ← ΦPΦᵀ + Q``."""
        phi = transition(dt)
        # stacked (B, 6, 1) product: the same arithmetic for every batch size (a 2-D
        # ``x @ phi.T`` switches between BLAS gemv and gemm with B)
        self.x = (phi @ self.x[:, :, None])[:, :, 0]
        self.P = phi @ self.P @ phi.T + process_noise(dt, self.q_horizontal, self.q_vertical)

    def update(self, ranges: np.ndarray, beacons: np.ndarray, depth: np.ndarray) -> None:
        """Update with the latest range of each beacon and the depth.

        Parameters
        ----------
        ranges : ndarray, shape (B, n)
            Latest range of each beacon [m]; NaN where none has been received.
        beacons : ndarray, shape (B, n, 3)
            Broadcast position of each beacon carried by that packet [m].
        depth : ndarray, shape (B,)
            Depth-sensor reading [m]; NaN to skip it.
        """
        batch, n = ranges.shape
        have = np.concatenate([np.isfinite(ranges), np.isfinite(depth)[:, None]], axis=1)
        h, H_r = range_and_jacobian(self.x, np.where(np.isfinite(beacons), beacons, 0.0))
        H = np.concatenate([H_r, np.broadcast_to(DEPTH_ROW, (batch, 1, STATE_SIZE))], axis=1)
        predicted = np.concatenate([h, self.x[:, 4:5]], axis=1)
        z = np.concatenate([ranges, depth[:, None]], axis=1)
        H = np.where(have[:, :, None], H, 0.0)
        y = np.where(have, z - predicted, 0.0)
        R = np.zeros((batch, n + 1, n + 1))
        diagonal = np.arange(n + 1)
        R[:, diagonal, diagonal] = np.column_stack([np.repeat(self.sigma_range[:, None] ** 2, n, axis=1),
                                                    self.sigma_depth**2])
        PHt = self.P @ np.swapaxes(H, 1, 2)
        S = H @ PHt + R
        # one factorization of S for the gain and the NIS: S⁻¹ [H P, y]
        solved = np.linalg.solve(S, np.concatenate([np.swapaxes(PHt, 1, 2), y[:, :, None]], axis=2))
        K = np.swapaxes(solved[:, :, :STATE_SIZE], 1, 2)
        self.x = self.x + np.einsum("bij,bj->bi", K, y)
        I_KH = np.eye(STATE_SIZE) - K @ H
        self.P = I_KH @ self.P @ np.swapaxes(I_KH, 1, 2) + K @ R @ np.swapaxes(K, 1, 2)
        self.y, self.S = y, S
        self.nis = np.einsum("bi,bi->b", y, solved[:, :, STATE_SIZE])
