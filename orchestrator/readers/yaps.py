"""The YAPS detections table (Baktoft et al. 2017, Sci. Rep. 7:14294): ``epo`` (whole seconds since 1970-01-01 UTC)
and ``frac`` (the fraction of that second, in [0, 1)), or ``ts`` alone (ISO 8601, UTC), ``tag`` and ``serial`` (the
receiver); a ``species`` column is kept; the others are ignored, named
(:func:`~sblsim.orchestrator.readers.detections.read_detections`)."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.times import utc_seconds
from sblsim.orchestrator.readers.cells import column, numbers, pattern, refuse, shown_header, whole_ids
from sblsim.orchestrator.readers.limits import IDENTIFIER, MAX_EPOCH

#: Whole seconds since 1970 (``epo``).
INTEGER = re.compile(r"[0-9]{1,11}")


def yaps(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
          ) -> tuple[pd.DataFrame, set[int]]:
    index = {key: column(header, (key,)) for key in ("epo", "frac", "ts", "tag", "serial", "species")}
    timed = (index["epo"] is not None and index["frac"] is not None) or index["ts"] is not None
    missing = [key for key in ("tag", "serial") if index[key] is None] + ([] if timed else ["epo and frac (or ts)"])
    if missing:
        raise ModelError(f"{what}: {name!r}: the header needs the columns epo, frac, tag, serial (or ts, tag, serial: "
                         f"YAPS); {', '.join(missing)} missing, got {shown_header(header)}")
    if index["epo"] is not None and index["frac"] is not None:
        epo = pattern(body[index["epo"]], INTEGER, what, name, lines, "epo",
                       f"whole seconds since 1970-01-01 UTC in [0, {MAX_EPOCH}]")
        seconds = epo.astype(np.int64).to_numpy()
        if (seconds > MAX_EPOCH).any():
            k = int(np.flatnonzero(seconds > MAX_EPOCH)[0])
            raise refuse(what, name, lines[k], "epo", epo.iloc[k], f"whole seconds in [0, {MAX_EPOCH}]")
        frac = numbers(body[index["frac"]], what, name, lines, "frac", 0.0, 1.0, high_open=True, unit="s")
        time = seconds + frac
        used = {index["epo"], index["frac"]}
    else:
        time = utc_seconds(body[index["ts"]], f"{what}: {name!r}", lines, header[index["ts"]])
        used = set()
    if index["ts"] is not None:
        used.add(index["ts"])
    tag = pattern(body[index["tag"]], IDENTIFIER, what, name, lines, "tag",
                   "an id of 1 to 40 letters, digits, '.', '_' or '-'")
    serial = pattern(body[index["serial"]], IDENTIFIER, what, name, lines, "serial",
                      "a receiver's serial of 1 to 40 letters, digits, '.', '_' or '-'")
    (tag, _), (serial, _) = whole_ids(tag), whole_ids(serial)  # 802357.0 as 802357, as the sheets read it
    frame = pd.DataFrame({"receiver": serial.to_numpy(), "tag": tag.to_numpy(), "code_space": "", "time": time,
                          "sensor_value": np.full(len(body), np.nan), "sensor_unit": ""})
    used |= {index["tag"], index["serial"]}
    if index["species"] is not None:
        frame["species"] = body[index["species"]].astype(str).str.strip().str.slice(0, 80).to_numpy()
        used.add(index["species"])
    return frame, used



__all__ = ["INTEGER", "yaps"]
