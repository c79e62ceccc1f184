"""The normal equations of a refinement of the receivers' positions from a tag's pings
(:func:`~sblsim.models.tracking.receiver_positions.refine_receivers`): the unknowns' layout, each Gauss-Newton
step's reduced system with each ping's and each anchored emission's own unknowns eliminated (Schur's complement),
and its solve.

The unknowns are each receiver's **range bias** at each knot [m], then its horizontal **shift** (x, y) [m], then,
where fitted, the **sound speed's scale** less 1 [1]. A range bias is one number per receiver (a constant offset of
its clock), or linear in time between knots at a synchronisation's bins' edges, as its clocks are (each receiver's
offset interpolated between its knots: :class:`~sblsim.models.sync.clock_fit.ClockFit`): a synchronisation made on
wrong positions leaves each receiver a clock error that changes from bin to bin, with the sync tags it hears. The
knots come first, in time order (an edge's receivers together): a ping or an emission in bin b touches the knots of
edges b and b + 1 only, so the knots' normal equations are block tridiagonal, with the shifts and the scale a
border, and a season of hourly knots is solved by
:func:`~sblsim.models.sync.selected_inversion.selected_inverse` (blocks × block³, not unknowns³).

References
----------
Triggs, McLauchlan, Hartley, Fitzgibbon, "Bundle adjustment — a modern synthesis", Vision Algorithms 1999, LNCS 1883
(§ 6.1: the points eliminated by Schur's complement); Takahashi, Fagan & Chin, "Formation of a sparse bus impedance
matrix and its application to short circuit study", PICA 1973 (the selected inverse).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from sblsim.models.declarations import ModelError
from sblsim.models.sync.selected_inversion import selected_inverse
from sblsim.models.tracking.smoother_cost import observed_information

#: Pings per chunk of the elimination (a chunk's (pings, R, R) products stay small).
CHUNK = 4096
#: The most unknowns solved densely (2000² doubles, 32 MB); beyond, the block-tridiagonal selected inverse.
DENSE_LIMIT = 2000


@dataclass(frozen=True)
class Unknowns:
    """The refinement's unknowns (the module docstring): ``receivers`` R, ``knots`` each receiver's range biases
    (0: none fitted; 1: a constant; K + 1: at ``edges`` (K + 1,) [s], linear in time between them), ``free`` the
    sound speed's scale fitted."""

    receivers: int
    knots: int
    free: bool
    edges: np.ndarray | None = None

    @classmethod
    def of(cls, receivers: int, biases: bool, edges, free: bool) -> "Unknowns":
        """The layout, ``edges`` checked (increasing, finite, at least two: else one constant bias)."""
        if not biases:
            return cls(receivers, 0, free)
        if edges is None:
            return cls(receivers, 1, free)
        edges = np.asarray(edges, float)
        if edges.ndim != 1 or len(edges) < 2 or not (np.isfinite(edges).all() and (np.diff(edges) > 0).all()):
            raise ModelError(f"receiver positions: the clocks' bins' edges {edges.shape}; allowed: increasing finite "
                             "times [s], two or more")
        return cls(receivers, len(edges), free, edges)

    @property
    def band(self) -> int:
        """The range biases' unknowns (first, in time order)."""
        return self.receivers * self.knots

    @property
    def size(self) -> int:
        return self.band + 2 * self.receivers + int(self.free)

    def bins(self, times: np.ndarray | None, rows: int) -> tuple[np.ndarray, np.ndarray]:
        """Each of ``rows`` times' bin (its first knot) and fraction of the bin [1] (clipped at the end knots)."""
        if self.knots <= 1:
            return np.zeros(rows, np.int64), np.zeros(rows)
        if times is None or np.shape(times) != (rows,) or not np.isfinite(times).all():
            raise ModelError(f"receiver positions: the pings' times {np.shape(times)}, "
                             f"{0 if times is None else int((~np.isfinite(times)).sum())} not finite; allowed: "
                             f"({rows},) finite times [s] where the biases have knots")
        k = np.clip(np.searchsorted(self.edges, times, side="right") - 1, 0, self.knots - 2)
        f = np.clip((times - self.edges[k]) / (self.edges[k + 1] - self.edges[k]), 0.0, 1.0)
        return k, f

    def bias(self, theta: np.ndarray, k: np.ndarray, f: np.ndarray) -> np.ndarray:
        """(n, R) [m] each receiver's range bias at ``n`` times of knots ``k`` and fractions ``f``."""
        if not self.knots:
            return np.zeros((len(k), self.receivers))
        knots = theta[:self.band].reshape(self.knots, self.receivers)
        if self.knots == 1:
            return np.broadcast_to(knots[0], (len(k), self.receivers))
        return knots[k] * (1.0 - f)[:, None] + knots[k + 1] * f[:, None]

    def columns(self, k: int) -> tuple[np.ndarray, int]:
        """The unknowns (R, c) of each receiver an arrival in bin ``k`` touches (its shift's x, y and its range
        biases' knots), and c."""
        n = self.receivers
        shift = self.band + 2 * np.arange(n)
        parts = [shift, shift + 1] + [b * n + np.arange(n) for b in ((k,) if self.knots == 1 else
                                                                     (k, k + 1) if self.knots else ())]
        return np.stack(parts, axis=1), len(parts)

    def shifts(self, theta: np.ndarray) -> np.ndarray:
        """(R, 2) [m] the shifts in ``theta``."""
        return theta[self.band:self.band + 2 * self.receivers].reshape(self.receivers, 2)

    def scale(self, theta: np.ndarray) -> float:
        """[1] the slowness's scale ``m`` (the sound speed ``c / m``)."""
        return 1.0 + float(theta[-1]) if self.free else 1.0


class Normal:
    """A reduced system assembled from dense blocks at given unknowns and sparse terms (duplicates summed)."""

    def __init__(self, size: int):
        self.size = size
        self.rows, self.cols, self.vals = [], [], []
        self.rhs = np.zeros(size)

    def block(self, at: np.ndarray, matrix: np.ndarray, vector: np.ndarray) -> None:
        """``matrix`` (c, c) and ``vector`` (c,) added at the unknowns ``at`` (c,)."""
        self.rows.append(np.repeat(at, len(at)))
        self.cols.append(np.tile(at, len(at)))
        self.vals.append(matrix.ravel())
        np.add.at(self.rhs, at, vector)

    def sparse(self, matrix: sp.spmatrix, vector: np.ndarray) -> None:
        coo = sp.coo_matrix(matrix)
        self.rows.append(coo.row)
        self.cols.append(coo.col)
        self.vals.append(coo.data)
        self.rhs += vector

    def matrix(self, prior: np.ndarray) -> sp.csr_matrix:
        """The assembled matrix with ``prior`` (size,) on its diagonal."""
        rows = np.concatenate(self.rows + [np.arange(self.size)])
        cols = np.concatenate(self.cols + [np.arange(self.size)])
        return sp.csr_matrix((np.concatenate(self.vals + [prior]), (rows, cols)), shape=(self.size, self.size))


def solve(matrix: sp.csr_matrix, rhs: np.ndarray, layout: Unknowns, covariance: bool = False):
    """``matrix⁻¹ rhs``, and with ``covariance`` the border's covariance (shifts, scale: (2R [+ 1], 2R [+ 1])) and
    each range bias's variance (band,): densely up to :data:`DENSE_LIMIT` unknowns, beyond by the selected inverse
    of the block-tridiagonal knots."""
    band = layout.band
    if band == 0 or layout.size <= DENSE_LIMIT:
        dense = matrix.toarray()
        if not covariance:
            return np.linalg.solve(dense, rhs), None, None
        whole = np.linalg.inv(dense)
        return whole @ rhs, whole[band:, band:], np.diag(whole)[:band].copy()
    x, selected = selected_inverse(matrix, band, np.arange(band), rhs,
                                   np.zeros((0, 2), np.int64) if covariance else None)
    return x, selected.border if covariance else None, selected.variance if covariance else None


def weights(e: np.ndarray, sigma: np.ndarray, dof: float, covariance: bool) -> np.ndarray:
    """Each arrival's Student-t weight over σ² [1/s²] (``(ν + 1) / (ν + z²)``), or its observed information's with
    ``covariance`` (0 past √ν σ: the robust smoother's covariance)."""
    zed = e / sigma
    if covariance:
        return observed_information(zed, dof) / sigma**2
    return (dof + 1.0) / (dof + zed**2) / sigma**2


def ping_terms(normal: Normal, layout: Unknowns, theta: np.ndarray, pings, sigma: np.ndarray, dof: float,
               min_arrivals: int, covariance: bool = False, studentised: bool = False):
    """A Gauss-Newton step's terms of the pings added to ``normal``, each ping's place and emission time eliminated
    (pings grouped by bin: a group's pings touch the same unknowns), and the pings' steps as a function of the
    receivers' (back-substitution: ``Δθ_j = A_j⁻¹ (b_j − B_j Δφ)``), and with ``studentised`` a function of the
    arrivals' residuals (P, R) [s] at the step's start, each over ``√(1 − h)`` (``h`` its leverage in its ping's
    fix; NaN where not heard), else None.

    ``pings`` holds ``toa`` (P, R) [s], ``heard`` (P, R), ``xy`` (P, 2) [m], ``t`` (P,) [s], ``z`` (P,) [m] or
    None, ``c`` (P,) [m/s], ``k`` and ``f`` (P,) each ping's bin and fraction."""
    receivers, toa, heard, xy, t, z, c = (pings[key] for key in ("receivers", "toa", "heard", "xy", "t", "z", "c"))
    n = layout.receivers
    d, m = layout.shifts(theta), layout.scale(theta)
    at = receivers[None, :, :2] + d[None]  # (1, R, 2)
    bias = layout.bias(theta, pings["k"], pings["f"])
    pieces = []
    order = np.argsort(pings["k"], kind="stable")  # the pings by bin, each bin's in their order
    groups, starts = np.unique(pings["k"][order], return_index=True)
    bounds = np.r_[starts, len(order)]
    for g, group in enumerate(groups):
        members = order[bounds[g]:bounds[g + 1]]
        at_columns, width = layout.columns(int(group))
        size = n * width + int(layout.free)
        block, vector = np.zeros((size, size)), np.zeros(size)
        for lo in range(0, len(members), CHUNK):
            rows = members[lo:lo + CHUNK]
            here = heard[rows]
            delta = xy[rows, None, :] - at  # (p, R, 2)
            vertical = 0.0 if z is None else (z[rows, None] - receivers[None, :, 2]) ** 2
            rho = np.sqrt((delta**2).sum(axis=2) + vertical)
            cc = c[rows, None]
            u = m * delta / np.maximum(rho, 1e-9)[..., None] / cc[..., None]  # ∂τ/∂p, (p, R, 2) [s/m]
            travel = (rho + bias[rows]) / cc  # ∂τ/∂m, (p, R) [s]
            e = np.where(here, toa[rows] - t[rows, None] - m * travel, 0.0)
            w = np.where(here, weights(e, sigma[None], dof, covariance), 0.0)  # (p, R) [1/s²]
            w[(w > 0).sum(axis=1) < min_arrivals] = 0.0  # a ping the observed information leaves too few: nothing
            g = np.concatenate([u, np.ones(u.shape[:2] + (1,))], axis=2)  # ∂τ/∂(x, y, t), (p, R, 3)
            slope = np.broadcast_to(m / cc, u.shape[:2])[..., None]  # ∂τ/∂(range bias), (p, R, 1)
            f = pings["f"][rows][:, None, None]
            h = np.concatenate([-u] + ([slope] if width == 3 else [slope * (1 - f), slope * f] if width == 4
                                       else []), axis=2)  # ∂τ/∂(the receivers' unknowns), (p, R, width)
            A = np.einsum("pr,pra,prb->pab", w, g, g)
            diagonal_a = A[:, np.arange(3), np.arange(3)]
            # a relative ridge (Levenberg's) keeps a ping of bad geometry invertible; an empty ping's the identity
            A[:, np.arange(3), np.arange(3)] = np.where(diagonal_a > 0, diagonal_a * (1.0 + 1e-10), 1.0)
            Ainv = np.linalg.inv(A)
            b = np.einsum("pr,pra,pr->pa", w, g, e)
            wg = w[..., None] * g
            # Σ_j w h hᵀ on the receivers' diagonal blocks; minus Σ_j B_jᵀ A_j⁻¹ B_j over every pair of receivers
            q = np.einsum("pia,pab,pkb->pik", wg, Ainv, wg)
            reduced = -np.einsum("pik,pia,pkb->iakb", q, h, h)
            reduced[np.arange(n), :, np.arange(n), :] += np.einsum("pr,pra,prb->rab", w, h, h)
            block[:n * width, :n * width] += reduced.reshape(n * width, n * width)
            Ab = np.einsum("pab,pb->pa", Ainv, b)
            vector[:n * width] += (np.einsum("pr,pra,pr->ra", w, h, e)
                                   - np.einsum("pra,pa,prb->rb", wg, Ab, h)).ravel()
            Bm = None
            if layout.free:  # the slowness's scale: one more unknown, every arrival's
                Bm = np.einsum("pra,pr->pa", wg, travel)  # B_j's column of m, (p, 3)
                AB = np.einsum("pab,pb->pa", Ainv, Bm)
                cross = (np.einsum("pr,pra,pr->ra", w, h, travel) - np.einsum("pra,pa,prb->rb", wg, AB, h)).ravel()
                block[:-1, -1] += cross
                block[-1, :-1] += cross
                block[-1, -1] += float(np.sum(w * travel**2) - np.einsum("pa,pa->", Bm, AB))
                vector[-1] += float(np.sum(w * travel * e) - np.einsum("pa,pa->", AB, b))
            # each arrival's residual over the root of the share its ping's own unknowns leave it
            shown = None if not studentised else np.where(here, e, np.nan) / np.sqrt(np.clip(
                1.0 - np.einsum("pra,pab,prb->pr", wg, Ainv, g), 0.05, 1.0))
            pieces.append((rows, Ainv, Ab, wg, h, Bm, at_columns, shown))
        where = np.r_[at_columns.ravel(), [layout.size - 1] if layout.free else []].astype(np.int64)
        normal.block(where, block, vector)

    def ping_steps(step: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        out = np.zeros((len(toa), 3))
        for rows, Ainv, Ab, wg, h, Bm, columns, _ in pieces:
            Bd = np.einsum("pra,prb,rb->pa", wg, h, step[columns])
            if Bm is not None:
                Bd = Bd + Bm * step[-1]
            out[rows] = Ab - np.einsum("pab,pb->pa", Ainv, Bd)
        return out[:, :2], out[:, 2]

    residuals = None
    if studentised:
        residuals = np.full(toa.shape, np.nan)
        for piece in pieces:
            residuals[piece[0]] = piece[-1]
    return ping_steps, residuals


class Anchored:
    """Pings emitted where a receiver is (a sync tag at its receiver): each one's place is that receiver's, shifted
    with it; its emission time its only unknown of its own. Each arrival at another receiver i of ping j from the
    receiver k: ``toa = t_j + (‖(r_k + d_k) − (r_i + d_i)‖ + β_i(t)) / c``."""

    def __init__(self, toa: np.ndarray, source: np.ndarray, c: float, t: np.ndarray,
                 bins: tuple[np.ndarray, np.ndarray]):
        self.toa, self.source, self.c, self.t = toa, source, c, t
        self.k, self.f = bins  # each emission's bin and fraction of it (Unknowns.bins)
        self.emission, self.receiver = np.nonzero(np.isfinite(toa))  # each arrival's emission and receiver
        self._steps = None

    @classmethod
    def of(cls, anchored, receivers: np.ndarray, c: float, layout: Unknowns) -> "Anchored":
        """From ``(toa, source)`` or ``(toa, source, times)``: each emission's times of arrival (Q, R) [s],
        receiver (Q,) and time (Q,) [s] (on the edges' base, where the biases have knots: each emission's bin in
        ``layout`` found once, its times refused in one line where they are missing)."""
        toa, source = np.asarray(anchored[0], float), np.asarray(anchored[1], int)
        times = np.asarray(anchored[2], float) if len(anchored) > 2 and anchored[2] is not None else None
        if toa.ndim != 2 or toa.shape[1] != len(receivers) or source.shape != (len(toa),) \
                or not ((source >= 0) & (source < len(receivers))).all() \
                or (times is not None and times.shape != (len(toa),)):
            raise ModelError(f"receiver positions: anchored pings {toa.shape} from {source.shape} receivers; allowed: "
                             f"(Q, {len(receivers)}) and (Q,) receiver indices (and (Q,) times)")
        toa = toa.copy()
        toa[np.arange(len(toa)), source] = np.nan  # a receiver's own tag: no distance to learn from
        keep = np.isfinite(toa).sum(axis=1) >= 2
        toa, source = toa[keep], source[keep]
        rho = np.linalg.norm(receivers[source][:, None, :] - receivers[None], axis=2)
        t = np.nanmedian(toa - rho / c, axis=1)
        return cls(toa, source, c, t, layout.bins(None if times is None else times[keep], len(toa)))

    def terms(self, normal: Normal, layout: Unknowns, receivers: np.ndarray, theta: np.ndarray, sigma: np.ndarray,
              dof: float, covariance: bool = False) -> None:
        """Their reduced terms in the receivers' unknowns added to ``normal``, each emission time eliminated; the
        emission times' steps kept for :meth:`advance`."""
        n = layout.receivers
        q, i = self.emission, self.receiver
        src = self.source[q]
        d, m = layout.shifts(theta), layout.scale(theta)
        where = np.array(receivers, float)
        where[:, :2] += d
        diff = where[src] - where[i]
        rho = np.linalg.norm(diff, axis=1)
        u = m * diff[:, :2] / np.maximum(rho, 1e-9)[:, None] / self.c  # ∂τ/∂(place), (a, 2)
        k, f = self.k[q], self.f[q]
        travel = (rho + layout.bias(theta, self.k, self.f)[q, i]) / self.c
        e = self.toa[q, i] - self.t[q] - m * travel
        w = weights(e, sigma[i], dof, covariance)
        # ∂τ/∂(the receivers' unknowns[, m]): the shifts of the receiver and of the source, the receiver's biases
        shift = layout.band + 2 * np.stack([i, i, src, src], axis=1) + np.array([0, 1, 0, 1])
        cols, vals = [shift], [np.c_[-u, u]]
        if layout.knots == 1:
            cols.append(i[:, None])
            vals.append(np.full((len(q), 1), m / self.c))
        elif layout.knots:
            cols.append(np.c_[k * n + i, (k + 1) * n + i])
            vals.append(m / self.c * np.c_[1 - f, f])
        if layout.free:
            cols.append(np.full((len(q), 1), layout.size - 1))
            vals.append(travel[:, None])
        cols, vals = np.hstack(cols), np.hstack(vals)
        J = sp.csr_matrix((vals.ravel(), (np.repeat(np.arange(len(q)), cols.shape[1]), cols.ravel())),
                          shape=(len(q), layout.size))
        E = sp.csr_matrix((np.ones(len(q)), (q, np.arange(len(q)))), shape=(len(self.toa), len(q)))
        WJ = sp.diags(w) @ J
        a = np.asarray(E @ w).ravel()  # each emission time's information
        b = np.asarray(E @ (w * e)).ravel()
        Bt = (E @ WJ).tocsr()
        inv = np.where(a > 0, 1.0 / np.maximum(a, 1e-300), 0.0)
        normal.sparse(J.T @ WJ - Bt.T @ sp.diags(inv) @ Bt, J.T @ (w * e) - Bt.T @ (inv * b))
        self._steps = (inv, b, Bt)

    def advance(self, step: np.ndarray) -> None:
        """The emission times moved with the receivers' step: ``Δt_j = (b_j − B_j Δφ) / a_j``."""
        inv, b, Bt = self._steps
        self.t = self.t + inv * (b - Bt @ step)


__all__ = ["CHUNK", "DENSE_LIMIT", "Anchored", "Normal", "Unknowns", "ping_terms", "solve", "weights"]
