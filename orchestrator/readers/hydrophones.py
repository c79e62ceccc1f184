"""The receivers (hydrophones) table of ``sblsim sync`` and ``toa``: ``serial``, ``sync_tag`` (the id of the sync tag at
that receiver, empty for none), ``x``, ``y`` [, ``z``] or ``x_m``, ``y_m`` [, ``z_m``] [m] in a local metric frame; an
``idx`` column is ignored (a study's deployment tables, in latitude and longitude, with dates:
:mod:`sblsim.orchestrator.readers.deployments`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.cells import column, file_table, numbers, pattern, whole_ids
from sblsim.orchestrator.readers.limits import IDENTIFIER, MAX_COORDINATE, MAX_HYDROPHONES


def read_hydrophones(path: Path | str) -> pd.DataFrame:
    """Read the receivers (hydrophones): ``serial``, ``sync_tag`` (empty: none), ``x``/``x_m``, ``y``/``y_m``
    [, ``z``/``z_m``] [m]; ``idx`` ignored.

    Returns
    -------
    pandas.DataFrame
        ``receiver`` (str), ``sync_tag`` (str, ``""`` for none), ``x``, ``y``, ``z`` [m] (``z`` NaN where the
        file gives no depths), in the file's order.

    Raises
    ------
    ModelError
        One line: a missing column, a bad serial or id, a coordinate outside [-1e7, 1e7] m, a serial or sync tag
        given twice.
    """
    path, what = Path(path), "receivers"
    name = str(path)
    header, body, lines = file_table(path, what, MAX_HYDROPHONES)
    if not len(body):
        raise ModelError(f"{what}: {name!r} holds a header and no receivers")
    serial = column(header, ("serial", "receiver", "name"))
    sync = column(header, ("sync_tag",))
    axes = [column(header, (f"{a}_m", a)) for a in "xyz"]
    if serial is None or axes[0] is None or axes[1] is None:
        raise ModelError(f"{what}: {name!r}: the header needs serial, x_m and y_m (or x, y) columns, optionally "
                         f"sync_tag and z_m; got {','.join(h[:20] for h in header[:12])}")
    receivers = pattern(body[serial], IDENTIFIER, what, name, lines, header[serial],
                         "a serial of 1 to 40 letters, digits, '.', '_' or '-'")
    if sync is not None:
        tags = body[sync].astype(str).str.strip()
        given = (tags != "").to_numpy()
        pattern(tags[given], IDENTIFIER, what, name, [lines[k] for k in np.flatnonzero(given)], header[sync],
                 "a tag id of 1 to 40 letters, digits, '.', '_' or '-', or empty")
    else:
        tags = pd.Series([""] * len(body))
    (receivers, _), (tags, _) = whole_ids(receivers), whole_ids(tags)  # 802357.0 as 802357, as the detections read it
    frame = pd.DataFrame({"receiver": receivers.to_numpy(), "sync_tag": tags.to_numpy()})
    for axis, k in zip("xyz", axes):
        frame[axis] = np.nan if k is None else numbers(body[k], what, name, lines, header[k], -MAX_COORDINATE,
                                                        MAX_COORDINATE, unit="m")
    twice = frame["receiver"][frame["receiver"].duplicated()]
    if len(twice):
        raise ModelError(f"{what}: {name!r}: receiver {twice.iloc[0]} is given twice")
    tags = frame["sync_tag"][frame["sync_tag"] != ""]
    if tags.duplicated().any():
        raise ModelError(f"{what}: {name!r}: sync tag {tags[tags.duplicated()].iloc[0]} is at two receivers; "
                         "allowed: one receiver per sync tag")
    return frame


__all__ = ["read_hydrophones"]
