"""The stretches of a season across which the clocks fitted from a study's moving tags' pings are linear (the pings
there too few to tie a knot: :func:`~sblsim.models.sync.knots.merged`), how far the clocks bend over such a length
where the pings do tie them (:func:`~sblsim.models.sync.knots.departure`), and the words the study's note says of
them (:func:`stretches_said`). Where the clocks bend more than the timing noise, a moving tag's rows in the stretch
are flagged ``clocks_interpolated`` (:func:`~sblsim.orchestrator.telemetry.study_offsets.interpolated`,
:mod:`~sblsim.orchestrator.tracks.row_flags`): the clocks' error there is in no row's σ.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sblsim.models.sync.knots import departure, stretch_counts


def sparse_stretches(edges: np.ndarray, grid: np.ndarray, times: np.ndarray, offsets: np.ndarray, tied: np.ndarray,
                     offset_sigma: np.ndarray, sigma: float) -> list[dict[str, Any]]:
    """The stretches between the fit's knots ``edges`` [s] that span more than one of the ``grid``'s windows (the
    pings were too few to tie a clock's offsets in each: :func:`~sblsim.models.sync.knots.merged`), each its
    ``start_s``, ``end_s`` [s since 1970 UTC], the pings fitted in it (``times`` [s], counted as
    :func:`~sblsim.models.sync.knots.merged` counts them), ``departure_s`` [s] how far the clocks (``offsets`` (R, K +
    1) [s] at ``edges``, less the time base's; ``tied`` the knots their arrivals touch; ``offset_sigma`` (R, K + 1)
    [s] their σ, the noise the departure is taken beyond) depart from a line over its length where the pings tie
    them (:func:`~sblsim.models.sync.knots.departure`; None: not seen) and ``rows_flagged``: that departure above the
    timing noise ``sigma`` [s] or not seen (the clocks are linear across the stretch, and a moving tag's rows in it
    are flagged ``clocks_interpolated``:
    :func:`~sblsim.orchestrator.telemetry.study_offsets.interpolated`)."""
    long = np.flatnonzero(np.diff(np.searchsorted(grid, edges)) > 1)
    counts = stretch_counts(edges, times)
    out = []
    for j in long:
        gone = departure(edges, offsets, tied, float(edges[j + 1] - edges[j]), offset_sigma)
        out.append({"start_s": float(edges[j]), "end_s": float(edges[j + 1]), "pings": int(counts[j]),
                    "departure_s": gone if np.isfinite(gone) else None, "rows_flagged": not gone <= sigma})
    return out


def stretches_said(stretches: list[dict[str, Any]]) -> str:
    """The note's words on the stretches the clocks are linear across (:func:`sparse_stretches`), or none."""
    if not stretches:
        return ""
    hours = [(s["end_s"] - s["start_s"]) / 3600.0 for s in stretches]
    flagged = [s for s in stretches if s["rows_flagged"]]
    seen = [s["departure_s"] for s in stretches if s["departure_s"] is not None]
    return (f"; the clocks linear across {len(stretches)} stretch{'es' if len(stretches) > 1 else ''} of too few "
            f"pings to follow them (the longest {max(hours):.3g} h, {sum(s['pings'] for s in stretches):,} pings "
            f"fitted in all): where the pings tie them they depart from a line over such a length by "
            + (f"up to {max(seen) * 1e3:.3g} ms (RMS)" if seen else "an unseen amount") + (
                f", more than the timing noise: a moving tag's rows in {len(flagged)} of them flagged "
                f"clocks_interpolated" if flagged else ", within the timing noise"))


__all__ = ["sparse_stretches", "stretches_said"]
