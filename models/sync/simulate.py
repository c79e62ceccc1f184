"""Simulated raw detections of sync tags: receivers whose clocks have an offset and a drift, each with a sync tag
at its position emitting at random burst intervals, heard by the receivers in range with a timing noise.

The truth of a receiver's clock: its time ``r = τ + a + b τ`` at the true time ``τ`` (offset ``a`` [s], drift
``b`` [s/s]); optionally one receiver's clock **jumps** by ``Δ`` [s] at ``τ_b`` (a reset, a download: ``r = τ + a + b
τ + Δ`` from then on; ``Δ < 0`` its time goes back). The offsets :func:`sblsim.models.sync.clocks.fit_clocks`
estimates are on the reference receiver's clock; :meth:`SimulatedSync.offset` gives that truth for any receiver at
its own clock's times.

The rows come in each receiver's order (receiver by receiver), and within a receiver by its clock's times
(``order="clock"``, the default) or by the true times (``order="logging"``: the order a receiver logs them and writes
them to its file, where a reset's readings after it follow those before it however their times compare; without a
jump back the two are the same).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.declarations import ModelError, shown

#: The rows' orders within a receiver (``order`` of :func:`simulate_sync` and :func:`tag_detections`).
ORDERS = ("clock", "logging")


@dataclass
class SimulatedSync:
    """Simulated sync-tag detections and their truth.

    Attributes
    ----------
    positions : numpy.ndarray
        (R, 2) [m] the receivers (sync tag ``j`` is at receiver ``j``).
    offset0, drift : numpy.ndarray
        (R,) [s], [s/s] each clock's offset at τ = 0 and its drift.
    receiver, tag : numpy.ndarray
        (n,) int, each detection's receiver and sync tag.
    time : numpy.ndarray
        (n,) [s] on the receiver's clock; the rows receiver by receiver, each's by its clock's time or in its order
        of logging (``order`` of :func:`simulate_sync`).
    emission : numpy.ndarray
        (n,) int, the true emission of each detection.
    echo : numpy.ndarray
        (n,) bool, a late multipath arrival.
    sound_speed : float
        [m/s].
    jump : (int, float, float) or None
        The clock jump: the receiver, the true time ``τ_b`` [s] and the size ``Δ`` [s]; None: no jump.
    after : numpy.ndarray or None
        (n,) bool, each detection logged after the jump (None without one).
    """

    positions: np.ndarray
    offset0: np.ndarray
    drift: np.ndarray
    receiver: np.ndarray
    tag: np.ndarray
    time: np.ndarray
    emission: np.ndarray
    echo: np.ndarray
    sound_speed: float
    jump: tuple[int, float, float] | None = None
    after: np.ndarray | None = None

    def _jumped(self, receiver: np.ndarray, time: np.ndarray, after: np.ndarray | None) -> np.ndarray:
        """(n,) [s] the jump in ``receiver``'s reading ``time``: Δ where logged after it (``after``; default a
        reading at or beyond the first one after the jump, ``r_b + Δ``; for a jump back the readings both clocks
        make count as before), else 0."""
        out = np.zeros(np.shape(time))
        if self.jump is None:
            return out
        j, tau_b, size = self.jump
        if after is None:
            first = tau_b + self.offset0[j] + self.drift[j] * tau_b + size
            after = np.asarray(time) >= (first if size >= 0 else first - size)
        return np.where((np.asarray(receiver) == j) & after, size, 0.0)

    def true_time(self, receiver: np.ndarray, time: np.ndarray, after: np.ndarray | None = None) -> np.ndarray:
        """(n,) [s] the true time τ of ``receiver``'s clock reading ``time`` (``after``: read after the jump,
        as :attr:`after`)."""
        return (time - self._jumped(receiver, time, after) - self.offset0[receiver]) / (1 + self.drift[receiver])

    def reading(self, receiver: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """(n,) [s] ``receiver``'s clock at the true time ``tau``, its jump included."""
        r = np.asarray(tau) + self.offset0[receiver] + self.drift[receiver] * np.asarray(tau)
        if self.jump is not None:
            j, tau_b, size = self.jump
            r = r + np.where((np.asarray(receiver) == j) & (np.asarray(tau) >= tau_b), size, 0.0)
        return r

    def offset(self, receiver: np.ndarray, time: np.ndarray, reference: int,
               after: np.ndarray | None = None) -> np.ndarray:
        """(n,) [s] the true offset of ``receiver`` at its clock's ``time`` against the ``reference`` receiver's
        clock: ``time`` minus the reference's reading at the same instant (``after`` as :meth:`true_time`)."""
        tau = self.true_time(receiver, time, after)
        return time - self.reading(np.full(np.shape(tau), reference), tau)


def simulate_sync(n_receivers: int = 20, hours: float = 24.0, seed: int = 0, side: float = 1000.0,
                  detection_range: float = 700.0, offset: float = 2.0, drift: float = 20e-6,
                  interval: tuple[float, float] = (540.0, 660.0), noise: float = 0.15e-3, p_detect: float = 0.9,
                  echo_share: float = 0.0, sound_speed: float = 1480.0,
                  jump: tuple[int, float, float] | None = None, order: str = "clock") -> SimulatedSync:
    """Simulate sync-tag detections (the module docstring).

    Parameters
    ----------
    n_receivers : int
        Receivers, each with its own sync tag, uniformly in a square of ``side`` [m].
    hours : float
        [h] the span.
    seed : int
        ``numpy.random.default_rng``'s seed.
    detection_range : float
        [m] a detection needs the receiver within this distance of the tag (its own tag always in range).
    offset, drift : float
        The clocks' offsets uniform in ±``offset`` [s], drifts uniform in ±``drift`` [s/s].
    interval : (float, float)
        [s] the burst interval's bounds (uniform).
    noise : float
        [s] the timing noise's sigma (Gaussian).
    p_detect : float
        The probability that a receiver in range logs an emission.
    echo_share : float
        The share of detections followed by a multipath echo, 0.5 to 5 ms late on the same receiver.
    sound_speed : float
        [m/s].
    jump : (int, float, float), optional
        One receiver's clock jump: the receiver, the true time [s] and the size [s] (the module docstring); the
        draws are the same with it or without.
    order : str
        Each receiver's rows by its clock's times (``"clock"``) or by the true times, as it logs them
        (``"logging"``: after a jump back its times go back once, at the jump); :data:`ORDERS`.

    Returns
    -------
    SimulatedSync

    Raises
    ------
    ModelError
        An ``order`` not in :data:`ORDERS`.
    """
    _check(order)
    rng = np.random.default_rng(seed)
    positions = rng.uniform(0, side, (n_receivers, 2))
    offset0 = rng.uniform(-offset, offset, n_receivers)
    drifts = rng.uniform(-drift, drift, n_receivers)
    span = hours * 3600.0
    distance = np.linalg.norm(positions[:, None] - positions[None], axis=2)
    rec, tag, tau, emission = [], [], [], []
    count = 0
    for i in range(n_receivers):
        n = int(span / interval[0]) + 2
        times = rng.uniform(0, interval[1]) + np.cumsum(rng.uniform(*interval, n))
        times = times[times < span]
        for t in times:
            hear = (distance[i] <= detection_range) & (rng.random(n_receivers) < p_detect)
            j = np.flatnonzero(hear)
            rec.append(j)
            tag.append(np.full(len(j), i))
            tau.append(t + distance[i, j] / sound_speed)
            emission.append(np.full(len(j), count))
            count += 1
    rec, tag, tau, emission = map(np.concatenate, (rec, tag, tau, emission))
    tau = tau + rng.normal(0, noise, len(tau))
    echo = np.zeros(len(tau), bool)
    if echo_share > 0:
        pick = rng.random(len(tau)) < echo_share
        rec, tag, emission = np.r_[rec, rec[pick]], np.r_[tag, tag[pick]], np.r_[emission, emission[pick]]
        tau = np.r_[tau, tau[pick] + rng.uniform(0.5e-3, 5e-3, pick.sum())]
        echo = np.r_[echo, np.ones(pick.sum(), bool)]
    clock = tau + offset0[rec] + drifts[rec] * tau
    after = None
    if jump is not None:
        after = (rec == jump[0]) & (tau >= jump[1])
        clock = clock + np.where(after, jump[2], 0.0)
    rows = np.lexsort((clock if order == "clock" else tau, rec))
    return SimulatedSync(positions, offset0, drifts, rec[rows], tag[rows], clock[rows], emission[rows],
                         echo[rows], sound_speed, None if jump is None else (int(jump[0]), float(jump[1]),
                                                                            float(jump[2])),
                         None if after is None else after[rows])


@dataclass
class TagDetections:
    """A tag's pings as raw detections on the receivers' own clocks (:func:`tag_detections`): ``receiver``,
    ``time`` [s] (the receiver's clock), ``ping`` (the simulator's row) and ``echo`` (a multipath copy), each (n,),
    receiver by receiver, each's by its clock's time or in its order of logging (``order`` of
    :func:`tag_detections`)."""

    receiver: np.ndarray
    time: np.ndarray
    ping: np.ndarray
    echo: np.ndarray


def tag_detections(toa: np.ndarray, offset0: np.ndarray, drift: np.ndarray, rng: np.random.Generator,
                   echo_share: float = 0.0, echo_delay: tuple[float, float] = (0.5e-3, 50e-3),
                   order: str = "clock") -> TagDetections:
    """A times-of-arrival matrix in true time (e.g. :func:`sblsim.models.tracking.simulate.simulate_pings`'s) as
    the receivers log it: each arrival ``τ`` read on receiver ``j``'s clock as ``τ + a_j + b_j τ`` (the module
    docstring's clocks: ``offset0`` (R,) [s], ``drift`` (R,) [s/s]); a share ``echo_share`` of the arrivals followed
    by a multipath echo ``U(echo_delay)`` [s] later on the same receiver; each receiver's rows by its clock's times
    (``order="clock"``) or by the true times, as it logs them (``"logging"``; the same here, its clock never going
    back: :data:`ORDERS`).

    Returns
    -------
    TagDetections

    Raises
    ------
    ModelError
        An ``order`` not in :data:`ORDERS`.
    """
    _check(order)
    ping, rec = np.nonzero(np.isfinite(toa))
    tau = toa[ping, rec]
    echo = np.zeros(len(tau), bool)
    if echo_share > 0:
        pick = rng.random(len(tau)) < echo_share
        ping, rec = np.r_[ping, ping[pick]], np.r_[rec, rec[pick]]
        tau = np.r_[tau, tau[pick] + rng.uniform(*echo_delay, pick.sum())]
        echo = np.r_[echo, np.ones(pick.sum(), bool)]
    clock = tau + offset0[rec] + drift[rec] * tau
    rows = np.lexsort((clock if order == "clock" else tau, rec))
    return TagDetections(rec[rows], clock[rows], ping[rows], echo[rows])


def _check(order: str) -> None:
    """Refuse an ``order`` not in :data:`ORDERS` in one line."""
    if order not in ORDERS:
        raise ModelError(f"order: {shown(order)} is not a rows' order; allowed: {', '.join(ORDERS)}")


def draw_clocks(n_receivers: int, offset: float, drift: float, rng: np.random.Generator,
                reference: int | None = 0) -> tuple[np.ndarray, np.ndarray]:
    """Each receiver's clock (the module docstring's ``a``, ``b``): its offset at τ = 0 uniform in ±``offset`` [s]
    and its drift uniform in ±``drift`` [s/s], the ``reference`` receiver's clock the true time (offset and drift 0:
    a receiver on GPS time, whose clock the others are synchronised to; None: every clock drawn).

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        (R,) offsets [s] and (R,) drifts [s/s].
    """
    offsets = rng.uniform(-offset, offset, n_receivers)
    drifts = rng.uniform(-drift, drift, n_receivers)
    if reference is not None:
        offsets[reference] = drifts[reference] = 0.0
    return offsets, drifts


def sync_tag_arrivals(positions: np.ndarray, span: float, interval: tuple[float, float], sound_speed: float,
                      p_detect: float, noise: float, rng: np.random.Generator
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The arrivals of a sync tag at each receiver (tag ``i`` at receiver ``i``'s position) in true time: each tag's
    first emission uniform in ``[0, interval[1])``, then intervals ``U(interval)``, until ``span`` [s]; each emission
    heard by every receiver (its own too) with the probability ``p_detect``, along the straight line at
    ``sound_speed`` [m/s], with a Gaussian timing noise of sigma ``noise`` [s].

    Parameters
    ----------
    positions : numpy.ndarray
        (R, 2) or (R, 3) [m] the receivers.
    p_detect : float or numpy.ndarray
        [0–1] the probability that a receiver hears an emission: one for every pair, or (R, R) with ``[i, j]``
        receiver ``j``'s of tag ``i`` (e.g. a detection range curve at their distance; a zero diagonal: a receiver
        deaf to its own tag). The draws are the same either way.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray, numpy.ndarray)
        Each arrival's receiver, its sync tag (int) and its time τ [s], in the order of emission.
    """
    positions = np.asarray(positions, dtype=float)
    n = len(positions)
    distance = np.linalg.norm(positions[:, None] - positions[None], axis=2)
    rec, tag, tau = [], [], []
    for i in range(n):
        count = int(span / interval[0]) + 2
        times = rng.uniform(0, interval[1]) + np.r_[0.0, np.cumsum(rng.uniform(*interval, count - 1))]
        times = times[times < span]
        heard = rng.random((len(times), n)) < (p_detect if np.ndim(p_detect) == 0 else np.asarray(p_detect)[i])
        e, j = np.nonzero(heard)
        rec.append(j)
        tag.append(np.full(len(j), i))
        tau.append(times[e] + distance[i, j] / sound_speed + rng.normal(0, noise, len(j)))
    return np.concatenate(rec), np.concatenate(tag), np.concatenate(tau)


def on_clocks(receiver: np.ndarray, tau: np.ndarray, offset0: np.ndarray, drift: np.ndarray) -> np.ndarray:
    """(n,) [s] true times ``tau`` read on ``receiver``'s clock: ``τ + a + b τ`` (the module docstring)."""
    return tau + offset0[receiver] + drift[receiver] * tau


__all__ = ["ORDERS", "SimulatedSync", "TagDetections", "draw_clocks", "on_clocks", "simulate_sync", "sync_tag_arrivals",
           "tag_detections"]
