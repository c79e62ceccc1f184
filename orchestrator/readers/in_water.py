"""The array a study uses: the deployments that were in the water and heard the study (:func:`in_water`).

A network's receiver sheet (GLATOS ``receiver_locations``, an OTN deployment table) lists every deployment of
the network over years; a study's detections come from a few of them. A deployment is **used** where its serial
logged at least one detection kept by :func:`~sblsim.orchestrator.readers.assign.assign` inside its window (from
its deployment to its recovery). The others are not used, each for one cause (the first that holds):

* ``serial_never_detected``: its serial is in no row of the detections;
* ``outside_detections_span``: its window does not overlap the kept detections' span (first to last);
* ``no_detection_in_window``: its serial logged detections, none of them kept inside its window.

The array is the used deployments: their extent, their frame (chosen again over them where it was chosen
automatically: :meth:`~sblsim.orchestrator.readers.deployments.Deployments.restricted`), the clocks and every tag's
matrix; the sheet's other deployments cost nothing more than their reading. Every deployment of the sheet stays
listed (``receivers.csv``: ``used``, ``not_used`` the cause, ``detections`` the kept detections).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from sblsim.orchestrator.readers.assign import Assigned
from sblsim.orchestrator.readers.deployments import Deployments
from sblsim.orchestrator.readers.detections import Detections

#: The causes of a deployment not used, as ``receivers.csv``'s ``not_used`` and ``study.json`` name them.
NOT_USED = ("serial_never_detected", "outside_detections_span", "no_detection_in_window")
#: Each cause as the console says it.
SAID = {"serial_never_detected": "serial never detected",
        "outside_detections_span": "outside the detections' time span",
        "no_detection_in_window": "no detection in its window"}
#: How many deployments not used the console's line names.
NAMED = 10


@dataclass
class InWater:
    """The array of :func:`in_water`.

    Attributes
    ----------
    deployments : Deployments
        The used deployments in their frame, with every deployment of the sheet as
        :attr:`~sblsim.orchestrator.readers.deployments.Deployments.sheet` (``used``, ``not_used``,
        ``detections``).
    assigned : Assigned
        The detections as assigned, their ``hydrophones`` the used deployments' (in that frame).
    """

    deployments: Deployments
    assigned: Assigned

    def line(self, listed: str = "listed in receivers.csv (used, not_used)") -> str | None:
        """The console's line on the deployments not used (None where every deployment is used): their count per
        cause, the first :data:`NAMED` of them by name, and ``listed``, where the output lists or counts them all
        (``sblsim sync`` writes no receivers.csv: its sync.json's ``receivers_file`` counts them)."""
        s = self.deployments.summary()
        gone = s["not_used"]
        if not gone["count"]:
            return None
        sheet = self.deployments.sheet
        names = sheet.loc[sheet["not_used"] != "", "receiver"].astype(str).tolist()
        shown = ", ".join(names[:NAMED]) + (f" and {len(names) - NAMED:,} more" if len(names) > NAMED else "")
        causes = ", ".join(f"{gone[k]:,} {SAID[k]}" for k in NOT_USED if gone.get(k))
        return (f"receivers: {s['used']:,} of {s['in_sheet']:,} deployments of {self.deployments.source} used (those "
                f"that logged a kept detection in their window); {gone['count']:,} not used ({causes}: {shown}): left "
                f"out of the frame, the clocks, the tracks and the map, {listed}")


def in_water(detections: Detections, assigned: Assigned, deployments: Deployments) -> InWater:
    """The deployments used and the others with their cause (the module docstring).

    Parameters
    ----------
    detections : Detections
        The detections as read (``receiver`` the serial logged).
    assigned : Assigned
        Their assignment to ``deployments`` (:func:`~sblsim.orchestrator.readers.assign.assign`).
    deployments : Deployments
        The sheet as read.

    Returns
    -------
    InWater
        The used deployments (``restricted``) and the assignment with their hydrophones only.

    Raises
    ------
    ModelError
        No deployment used (none of the detections kept; :func:`assign` refuses that first).
    """
    kept = assigned.detections.frame
    times = kept["time"].to_numpy(float)
    span = (float(times.min()), float(times.max())) if len(times) else (np.inf, -np.inf)
    return counted_in_water(kept["receiver"].value_counts(), span, detections.frame["receiver"].unique(), assigned,
                            deployments)


def counted_in_water(kept: pd.Series, span: tuple[float, float], serials, assigned: Assigned,
                     deployments: Deployments) -> InWater:
    """:func:`in_water` from what it takes of the detections: the kept detections per deployment (``kept``, by the
    deployment's name), their first and last times [s] (``span``) and the serials logged, as a study of a store
    counts them a batch of tags at a time (:mod:`sblsim.orchestrator.telemetry.study_detections`)."""
    table = deployments.table
    count = table["receiver"].map(kept).fillna(0).astype(np.int64).to_numpy()
    used = count > 0
    first, last = span
    logged = table["serial"].isin(list(serials)).to_numpy()
    overlaps = ((table["start"].to_numpy(float) <= last) & (table["end"].to_numpy(float) >= first))
    cause = np.select([used, ~logged, ~overlaps], ["", NOT_USED[0], NOT_USED[1]], NOT_USED[2]).astype(object)
    array = deployments.restricted(used, {"used": used, "not_used": cause, "detections": count})
    hydrophones = assigned.hydrophones[used].reset_index(drop=True)
    for key in ("x", "y", "z"):  # in the array's frame
        hydrophones[key] = array.table[key].to_numpy(float)
    return InWater(array, replace(assigned, hydrophones=hydrophones))


__all__ = ["InWater", "NOT_USED", "SAID", "counted_in_water", "in_water"]
