"""What ``sblsim toa`` says on a built times-of-arrival matrix: its console lines (:func:`run_lines`) and a
build's warnings on stderr (:func:`say_warnings`, ``sblsim sync``'s too).
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from sblsim.models.tracking.timing import SIGMA_TOA


def run_lines(outcome, where: str) -> list[str]:
    """The console's lines on a built matrix."""
    s = outcome.summary
    d = s["detections"]
    heard = s["heard_per_ping"]
    lines = [f"times of arrival of tag {s['tag']}: {s['pings']} pings at {len(s['receivers'])} receivers from "
             f"{d['of_tag']} detections ({d['used']} used, {d['multipath']} multipath echoes dropped, "
             f"{d['outside_sync_span']} outside the synchronised span, "
             + (f"{d['at_clock_breaks']} at clock breaks (set aside), " if d.get("at_clock_breaks") else "")
             + f"{d['at_receivers_not_in_table']} at receivers "
             f"not in the table, {d['at_receivers_not_synchronised']} at receivers not synchronised) in "
             f"{s['wall_time_s']:.2f} s",
             f"  window {s['window_s'] * 1e3:.0f} ms (the array's largest travel time at 1300 m/s and 20 ms), shortest "
             f"burst interval {s['shortest_interval_s']:.4g} s ({s['shortest_interval_source']}); receivers per ping: "
             + ", ".join(f"{k}: {v}" for k, v in heard.items()),
             f"  time base of toa.txt: {s['origin_epoch_s']:.0f} s since 1970-01-01 UTC"
             + (f"; sensor values per ping: {', '.join(s['sensors'])}" if s["sensors"] else "")]
    if "positions" in s:
        each = s["positions"].get("sigma_m")
        lines.append(f"  receivers' positions: {s['positions']['receivers']} from the synchronisation's "
                     "positions.csv (refined)" + (
                         f"; each one's error in the tracker's σ (receivers.csv's sigma_m): {min(each.values()):.3g} "
                         f"to {max(each.values()):.3g} m per axis" if each else ""))
    elif outcome.survey_sigma is not None:
        lines.append(f"  survey error the synchronisation saw in its residuals between receivers: "
                     f"{outcome.survey_sigma:.3g} m per axis, taken as the survey's error in the tracker's σ "
                     "(receivers.csv's sigma_m)")
    noise = s.get("toa_sigma_s")
    if noise:
        values = np.array(list(noise.values()))
        lines.append(f"  TOA noise per receiver from the synchronisation's residuals (receivers.csv's toa_sigma_s, "
                     f"the tracker's): median {np.median(values) * 1e3:.3g} ms, {values.min() * 1e3:.3g} to "
                     f"{values.max() * 1e3:.3g} ms")
    elif noise is None and "toa_sigma_s" in s:
        lines.append("  TOA noise: the synchronisation's offsets.csv gives none (written before its toa_sigma_s): the "
                     f"tracker will assume {SIGMA_TOA * 1e3:g} ms (give --toa-sigma to the replay)")
    if where:
        lines.append(f"  written to {where}/ (toa.txt, receivers.csv, pings.csv, toa.json)")
    return lines


def say_warnings(summary: dict[str, Any]) -> None:
    """A built matrix's warnings (``summary["warnings"]``: times rounded too coarsely), each a line on stderr."""
    for warning in summary.get("warnings", []):
        print(f"sblsim: warning: {warning}", file=sys.stderr)


__all__ = ["run_lines", "say_warnings"]
