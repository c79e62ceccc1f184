"""A network's detection extract (GLATOS's, OTN's) as detections: each field found by the names :mod:`.glatos` and
:mod:`.otn` declare for it, checked cell by cell."""

from __future__ import annotations

import re

import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.times import utc_seconds
from sblsim.orchestrator.readers.cells import column, pattern, shown_header
from sblsim.orchestrator.readers.sensors import sensor_columns
from sblsim.orchestrator.readers.transmitters import CODE_SPACE, FULL_ID, TAG_ID, full_ids, split

#: A receiver's serial as the exports give it (``VR2W-128355`` keeps ``128355``).
RECEIVER = re.compile(r"(?:[A-Za-z0-9._]{1,20}-){0,2}[A-Za-z0-9._]{1,40}")


def extract(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str, network: str,
             names: dict[str, tuple[str, ...]]) -> tuple[pd.DataFrame, set[int]]:
    """A network's detection extract: ``names`` gives each of ``time``, ``receiver``, ``full_id``, ``space``,
    ``id``, ``value``, ``unit``, ``station`` the header names it may have (case ignored)."""
    index = {key: column(header, aliases) for key, aliases in names.items()}
    has_tag = index["full_id"] is not None or index["id"] is not None
    missing = [names[key][0] for key in ("time", "receiver") if index[key] is None] + \
        ([] if has_tag else [names["full_id"][0]])
    if missing:
        raise ModelError(f"{what}: {name!r}: an {network} detection extract needs the columns "
                         f"{', '.join(names[k][0] for k in ('time', 'receiver'))} and "
                         f"{names['full_id'][0]} (or {names['space'][0]} and {names['id'][0]}); "
                         f"{', '.join(missing)} missing, got {shown_header(header)}")
    time = utc_seconds(body[index["time"]], f"{what}: {name!r}", lines, header[index["time"]])
    receiver = pattern(body[index["receiver"]], RECEIVER, what, name, lines, header[index["receiver"]],
                       "a receiver's serial (or MODEL-SERIAL, e.g. VR2W-128355)").str.rpartition("-")[2]
    if index["full_id"] is not None and (index["id"] is None or index["space"] is None):
        tag = pattern(body[index["full_id"]], FULL_ID, what, name, lines, header[index["full_id"]],
                      "a transmitter's full ID CODESPACE-ID, e.g. A69-1602-4555")
    else:
        space = pattern(body[index["space"]], CODE_SPACE, what, name, lines, header[index["space"]],
                        "a code space, e.g. A69-1602") if index["space"] is not None else \
            pd.Series([""] * len(body))
        ident = pattern(body[index["id"]], TAG_ID, what, name, lines, header[index["id"]],
                        "a transmitter's id of 1 to 40 letters, digits, '.' or '_'")
        tag = full_ids(space, ident)
    frame = pd.DataFrame({"receiver": receiver.to_numpy(), "tag": tag.to_numpy(),
                          "code_space": [split(t)[0] for t in tag], "time": time})
    frame["sensor_value"], frame["sensor_unit"] = sensor_columns(body, index["value"], index["unit"], header, lines,
                                                                 name, what)
    if index["station"] is not None:
        frame["station"] = body[index["station"]].astype(str).str.strip().str.slice(0, 80).to_numpy()
    return frame, {k for k in index.values() if k is not None}


__all__ = ["RECEIVER", "extract"]
