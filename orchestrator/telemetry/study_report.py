"""The console's lines of a telemetry study before its tags are tracked (``sblsim track``): the detections, the
frame, the clocks, the timing noise, the water's depth and the tags, made from the study's summary.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from sblsim.orchestrator.tracks.depth import water_line
from sblsim.orchestrator.tracks.tracker import noise_line


def opening_lines(detections: Path, s: dict[str, Any], count: int, options: dict[str, Any]) -> list[str]:
    """The console's lines before the tracking: the detections, the frame, the clocks, the tags."""
    d, r, c = s["detections"], s["receivers"], s["clocks"]
    why = d["reasons"]
    frame = s["frame"]
    where = (f"frame {frame['name']} ({frame['crs']}, {frame['chosen']}; scale factor "
             f"{frame.get('scale_factor', float('nan')):.5f})") if frame else \
        "a local frame without a CRS (no lat/lon out)"
    out = [f"study of {detections} ({d['format']}): {d['rows']} detections, {d['used']} used at {r['deployments']} "
           f"deployments of {r['receivers']} receivers, {d['set_aside']} set aside ({why['outside_deployment']} "
           f"outside a deployment, {why['receiver_not_in_table']} at serials not in the receivers file, "
           f"{why['sync_tag_outside_deployment']} of sync tags out of the water); {d['first_utc']} to {d['last_utc']}",
           f"  {where}"]
    if c["source"] == "synchronised here":
        out.append(f"  clocks synchronised here against {c['reference_receiver']}: {c['receivers']} receivers, median "
                   f"|residual| {c['median_abs_residual_m']:.3g} m" + (f"; not synchronised: "
                                                                      f"{', '.join(c['not_synchronised'])}"
                                                                      if c["not_synchronised"] else ""))
    elif c["source"] == "given":
        out.append(f"  clocks from {c['folder']} ({c['receivers']} receivers, positions {c['positions']})")
    else:
        out.append("  clocks taken as logged (no sync tag in the receivers file)")
    if "toa_noise" in s:
        out.append("  " + noise_line(s["toa_noise"]))
    if s.get("water_depth"):
        out.append("  " + water_line(s["water_depth"]))
    where = "on " + options["scheduler"] if options["scheduler"] else \
        f"in {min(options['workers'] or os.cpu_count() or 1, max(count, 1))} worker processes"
    out.append(f"  tracking {count} tags {where}")
    return out


__all__ = ["opening_lines"]
