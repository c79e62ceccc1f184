"""The arrivals a track uses: the times of arrival's columns matched to the receivers (by the header's names, else
by order), those without a position, never heard or not kept (``receivers_kept``) dropped, and a share of the
detections removed at random (``drop_detections``, seeded).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from sblsim.models.declarations import ModelError


def _usable(toa_matrix, receivers, kept: Sequence[str] | None = None) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The TOA columns matched to the receivers (by the header's names, else by order), those without a position,
    never heard or (``kept`` given) not kept dropped: times (m, k), positions (k, dim), names (k)."""
    if toa_matrix.names is not None:
        missing = [n for n in toa_matrix.names if n not in receivers.names]
        if missing:
            raise ModelError(f"toa: the receiver {missing[0]!r} of the header is not in the receivers file")
        order = [receivers.names.index(n) for n in toa_matrix.names]
    else:
        if toa_matrix.toa.shape[1] != len(receivers.names):
            raise ModelError(f"toa: {toa_matrix.toa.shape[1]} columns and {len(receivers.names)} receivers; allowed: "
                             "one column per receiver, in the receivers file's order (or a header of their names)")
        order = list(range(len(receivers.names)))
    positions = receivers.positions[order]
    keep = np.isfinite(positions).all(axis=1) & np.isfinite(toa_matrix.toa).any(axis=0)
    if kept is not None:
        unknown = [n for n in kept if n not in receivers.names]
        if unknown:
            shown = ", ".join(receivers.names[:40]) + (", ..." if len(receivers.names) > 40 else "")
            raise ModelError(f"receivers_kept: {unknown[0][:40]!r} is not a receiver; allowed: names of the "
                             f"receivers file ({shown})")
        keep &= np.array([receivers.names[k] in kept for k in order])
    if keep.sum() < positions.shape[1] + 1:
        raise ModelError(f"receivers: {int(keep.sum())} receivers with a position heard a ping" +
                         (" among those kept" if kept is not None else "") +
                         f"; allowed: at least {positions.shape[1] + 1}")
    return toa_matrix.toa[:, keep], positions[keep], [receivers.names[k] for k, ok in zip(order, keep) if ok]


def drop_detections(toa: np.ndarray, share: float, seed: int) -> tuple[np.ndarray, int]:
    """``toa`` (m, n) [s] with each detection removed (NaN) with probability ``share``, drawn by
    ``numpy.random.default_rng(seed)`` (one uniform number per cell, heard or not); returns the matrix and the
    number of detections removed."""
    if share <= 0:
        return toa, 0
    gone = np.isfinite(toa) & (np.random.default_rng(seed).random(toa.shape) < share)
    return np.where(gone, np.nan, toa), int(gone.sum())



__all__ = ["drop_detections"]
