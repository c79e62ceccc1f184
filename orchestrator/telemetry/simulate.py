"""A simulated telemetry study written as its people bring one: a deployments sheet in latitude and longitude with
dates (OTN's names; receivers redeployed to another station, each with a co-located sync tag), the receivers' raw
detections on their own drifting clocks as a VUE export or a Fathom CSV, and a tag sheet of animals at every ping
type; with the truth (each tag's emissions and positions, each deployment's clock) to score what is made of them.

The array is a jittered grid of receivers ``spacing`` apart around ``centre`` (projected in its UTM zone), each
deployment's clock ``τ + a + b τ + w sin(2π τ / T + φ)`` at the true time ``τ`` (seconds from the study's start; ``a``
uniform in ±``offset``, ``b`` in ±``drift``, ``w`` in ±``wander``, ``T`` in one to three days, ``φ`` in a turn: a
crystal's rate following the water's temperature, which a drift corrected at offload as a line leaves; a redeployed
receiver's clock set again at its redeployment). A receiver hears an
emission at distance ``d`` with the logistic detection range curve ``1 / (1 + exp((d − r50) / (r50 / 6)))``
(50 % at ``range_50``), along the straight line at ``sound_speed`` (one, or the water's at each emission: a season's
water warms and cools), with a Gaussian timing noise ``sigma_toa``;
only while it is deployed. A redeployed receiver, out of the water for an hour (a tenth of a short study), logs
its own sync tag on deck between its two deployments: detections a study must set aside. The animals move along
smooth paths inside the array (sums of sinusoids of periods of hours), emitting with a stable (``sbi``), random
(``rbi``) or pseudo-random (``pbi``) burst interval in turn; sync tags at a random interval of 540 to 660 s
(Vemco's).
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import pandas as pd

from sblsim.orchestrator.io.frames import Frame, utm_zone
from sblsim.orchestrator.io.times import iso_utc, parse_instant

#: The sync tags' random burst interval [s].
SYNC_INTERVAL = (540.0, 660.0)
#: The animal tags' intervals [s]: a stable one drawn per tag in this range, a random one's bounds, a pseudo-random
#: sequence's values.
SBI_RANGE = (120.0, 180.0)
RBI_BOUNDS = (100.0, 200.0)
PBI_RANGE = (100.0, 200.0)
#: A stable interval's emission jitter [s].
SBI_JITTER = 1e-3
#: The code spaces of the sync and the animal tags.
SYNC_SPACE, ANIMAL_SPACE = "A69-1601", "A69-1602"


@dataclass
class SimulatedStudy:
    """A simulated study (the module docstring).

    Attributes
    ----------
    deployments : pandas.DataFrame
        The deployments sheet: ``station``, ``ins_serial_no``, ``deploy_lat``, ``deploy_long``,
        ``deploy_date_time``, ``recover_date_time`` (ISO 8601 UTC), ``transmitter`` (the sync tag's full ID).
    detections : pandas.DataFrame
        ``serial``, ``model``, ``transmitter`` (full ID), ``time`` [s since 1970 UTC on the receiver's clock], in
        each receiver's order of logging.
    sheet : pandas.DataFrame
        The tag sheet: ``transmitter``, ``ping_type``, ``min_delay``, ``max_delay``, ``interval``,
        ``burst_sequence``, ``role``.
    sequences : dict
        Each ``pbi`` tag's file name and its intervals [s].
    truth : dict
        Each animal's truth (full ID -> DataFrame of ``tau`` [s from the start], ``x``, ``y`` [m in the frame]).
    clocks : pandas.DataFrame
        Each deployment's clock: ``deployment`` (its position in ``deployments``), ``serial``, ``a`` [s], ``b``
        [s/s], ``w`` [s], ``period`` [s], ``phase`` [rad] (:meth:`offset`), ``start``, ``end`` [s from the start].
    frame : Frame
        The UTM zone of the centre.
    origin : float
        [s since 1970 UTC] the study's start.
    positions : numpy.ndarray
        (deployments, 2) [m] in the frame.
    """

    deployments: pd.DataFrame
    detections: pd.DataFrame
    sheet: pd.DataFrame
    sequences: dict[str, np.ndarray]
    truth: dict[str, pd.DataFrame]
    clocks: pd.DataFrame
    frame: Frame
    origin: float
    positions: np.ndarray = field(repr=False, default=None)

    def offset(self, deployment: int, tau: np.ndarray) -> np.ndarray:
        """[s] deployment ``deployment``'s clock's offset at the true times ``tau`` [s from the start]:
        ``a + b τ + w sin(2π τ / T + φ)`` (the module docstring)."""
        a, b = self.clocks.loc[deployment, ["a", "b"]]
        return a + b * tau + _wander(self.clocks, np.full(np.shape(tau), deployment), np.asarray(tau, float))

    def clock_time(self, deployment: int, tau: np.ndarray) -> np.ndarray:
        """[s since 1970 UTC] deployment ``deployment``'s clock reading at the true times ``tau`` [s from the
        start] (summed in the order a study without wander always was: the same times to the bit)."""
        a, b = self.clocks.loc[deployment, ["a", "b"]]
        return self.origin + tau + a + b * tau + _wander(self.clocks, np.full(np.shape(tau), deployment),
                                                         np.asarray(tau, float))

    def truth_at(self, tag: str, epoch: np.ndarray, deployment: int) -> np.ndarray:
        """(n, 2) [m in the frame] animal ``tag``'s true position at the times ``epoch`` (n,) [s since 1970 UTC]
        read on deployment ``deployment``'s clock (the reference receiver's: a synchronised study's UTC), its truth
        interpolated linearly between its samples."""
        truth = self.truth[tag]
        on_clock = self.clock_time(deployment, truth["tau"].to_numpy())
        epoch = np.asarray(epoch, float)
        return np.c_[np.interp(epoch, on_clock, truth["x"]), np.interp(epoch, on_clock, truth["y"])]

    def with_reference_tags(self, at, positions: np.ndarray | None = None
                            ) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
        """The study's tables with the sync tags of deployments ``at`` (their rows in ``deployments``) given as
        reference tags at their receivers, as a study with reference tags brings them: the deployments with those
        sync-tag cells emptied (the other sync tags synchronise) and, where ``positions`` (deployments, 2) [m in the
        frame] are given, their latitude and longitude there (a survey's, off from the truth); the tag sheet with
        their ``role`` ``reference`` and a ``receiver`` column naming each one's station (empty for the other
        tags); their transmitters, in ``at``'s order. The tags stay where they were simulated: at their receivers'
        true positions (``positions`` of this study)."""
        deployments = self.deployments.copy()
        if positions is not None:
            lat, lon = self.frame.to_latlon(positions[:, 0], positions[:, 1])
            deployments = deployments.assign(deploy_lat=lat, deploy_long=lon)
        rows = deployments.index[list(at)]
        references = deployments.loc[rows, "transmitter"].tolist()
        sheet = self.sheet.copy()
        sheet.loc[sheet["transmitter"].isin(references), "role"] = "reference"
        sheet["receiver"] = sheet["transmitter"].map(dict(zip(references, deployments.loc[rows, "station"]))
                                                     ).fillna("")
        deployments.loc[rows, "transmitter"] = ""
        return deployments, sheet, references

    def write(self, folder: Path | str, format: str = "vue") -> dict[str, Path]:
        """Write the study's files into ``folder``: ``deployments.csv``, ``tags.csv`` (and each ``pbi`` tag's
        sequence), and ``detections.csv`` as a VUE export (``vue``), a Fathom CSV (``fathom``) or a GLATOS
        detection extract (``glatos``); returns their paths by name."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        self.deployments.to_csv(folder / "deployments.csv", index=False, float_format="%.10f")
        self.sheet.to_csv(folder / "tags.csv", index=False)
        for name, values in self.sequences.items():
            pd.DataFrame({"interval_s": values}).to_csv(folder / name, index=False, float_format="%.6f")
        path = folder / "detections.csv"
        writers = {"vue": vue_text, "fathom": fathom_text, "glatos": glatos_text}
        if format not in writers:
            raise ValueError(f"format: {format!r} is not one of {', '.join(writers)}")
        path.write_text(writers[format](self.detections))
        return {"deployments": folder / "deployments.csv", "tags": folder / "tags.csv", "detections": path}


def vue_text(detections: pd.DataFrame) -> str:
    """Detections as a VUE export (its header and columns; times ISO 8601 UTC to the microsecond)."""
    frame = pd.DataFrame({"Date and Time (UTC)": [t.replace("T", " ").rstrip("Z") for t in
                                                  iso_utc(detections["time"].to_numpy())],
                          "Receiver": detections["model"] + "-" + detections["serial"],
                          "Transmitter": detections["transmitter"], "Transmitter Name": "", "Transmitter Serial": "",
                          "Sensor Value": "", "Sensor Unit": "", "Station Name": "", "Latitude": "",
                          "Longitude": ""})
    return frame.to_csv(index=False)


#: A GLATOS detection extract's columns (the GLATOS data dictionary's, in its order).
GLATOS_COLUMNS = ("animal_id,detection_timestamp_utc,glatos_array,station_no,transmitter_codespace,transmitter_id,"
                  "sensor_value,sensor_unit,deploy_lat,deploy_long,receiver_sn,tag_type,tag_model,tag_serial_number,"
                  "common_name_e,capture_location,length,weight,sex,release_group,release_location,release_latitude,"
                  "release_longitude,utc_release_date_time,glatos_project_transmitter,glatos_project_receiver,"
                  "glatos_tag_recovered,glatos_caught_date,station,min_lag").split(",")


def glatos_text(detections: pd.DataFrame) -> str:
    """Detections as a GLATOS detection extract (its 30 columns; a database query's order: by animal, then time; the
    times ISO 8601 UTC to the microsecond; the animal's and the project's columns filled as an extract has them)."""
    space, _, ident = detections["transmitter"].str.rpartition("-").T.to_numpy()
    times = [t.replace("T", " ").rstrip("Z") for t in iso_utc(detections["time"].to_numpy())]
    frame = pd.DataFrame({name: "" for name in GLATOS_COLUMNS}, index=range(len(detections)))
    frame = frame.assign(animal_id=["A" + i for i in ident], detection_timestamp_utc=times, glatos_array="SIM",
                         station_no=detections["serial"].to_numpy(), transmitter_codespace=space,
                         transmitter_id=ident, deploy_lat="56.0", deploy_long="9.0",
                         receiver_sn=detections["serial"].to_numpy(), tag_type="pinger", tag_model="V9-2x",
                         common_name_e="brown trout", glatos_project_transmitter="SIM",
                         glatos_project_receiver="SIM", station=detections["serial"].to_numpy(), min_lag="NA")
    order = np.lexsort((detections["time"].to_numpy(), frame["animal_id"].to_numpy()))
    return frame.iloc[order].to_csv(index=False)


def fathom_text(detections: pd.DataFrame) -> str:
    """Detections as a Fathom CSV (its first line, the record-type line, the DET_DESC line and the DET records of
    its format 2; the times ISO 8601 to the microsecond), with a TEMP record each hundredth line."""
    columns = ["Device Time (UTC)", "Time", "Time Offset (h)", "Time Correction (s)", "Model", "Serial Number",
               "Channel", "Detection Type", "Full ID", "ID", "Raw Data", "Transmitter Serial",
               "Signal Strength (dB)", "Noise (dB)", "Gain (dB)", "Quality Score", "Station Name", "Latitude",
               "Longitude", "GPS HDOP"]
    times = [t.replace("T", " ").rstrip("Z") for t in iso_utc(detections["time"].to_numpy())]
    det = pd.DataFrame({"record": "DET", "device": times, "time": times, "offset": "+0", "correction": "0",
                        "model": detections["model"].to_numpy(), "serial": detections["serial"].to_numpy(),
                        "channel": "1", "kind": "PPM", "full": detections["transmitter"].to_numpy(),
                        "id": [t.rpartition("-")[2] for t in detections["transmitter"]], "raw": "", "tserial": "",
                        "signal": "120", "noise": "40", "gain": "0", "quality": "100", "station": "", "lat": "",
                        "lon": "", "hdop": ""})
    body = det.to_csv(index=False, header=False).splitlines()
    temp = "TEMP,{t},{t},+0,0,{m},{s},9.5,10.0"
    lines = []
    for k, line in enumerate(body):
        lines.append(line)
        if k % 100 == 0:
            lines.append(temp.format(t=times[k], m=det["model"].iloc[k], s=det["serial"].iloc[k]))
    out = io.StringIO()
    out.write("VEMCO DATA LOG,2.0.0,sblsim-simulated\n")
    out.write("RECORD TYPE," + ",".join(["FIELD"] * len(columns)) + "\n")
    out.write("DET_DESC," + ",".join(columns) + "\n")
    out.write("TEMP_DESC,Device Time (UTC),Time,Time Offset (h),Time Correction (s),Model,Serial Number,"
              "Ambient (deg C),Internal (deg C)\n")
    out.write("\n".join(lines) + "\n")
    return out.getvalue()


def _path(rng: np.random.Generator, centre: np.ndarray, half: float):
    """A smooth path inside a square of half-width ``half`` around ``centre``: per axis, two sinusoids of periods of
    2 to 9 hours, random phases, amplitudes summing to 0.8 ``half``; a function of ``tau`` (n,) [s] -> (n, 2) [m]."""
    periods = rng.uniform(2 * 3600, 9 * 3600, (2, 2))
    phases = rng.uniform(0, 2 * np.pi, (2, 2))
    weights = rng.dirichlet([2, 2], 2) * 0.8 * half

    def at(tau: np.ndarray) -> np.ndarray:
        tau = np.asarray(tau, float)[:, None, None]
        return centre + (weights * np.sin(2 * np.pi * tau / periods + phases)).sum(axis=2)

    return at


def _emissions(kind: str, span: float, rng: np.random.Generator, figures) -> np.ndarray:
    """[s from the start] a tag's emissions over ``span`` [s]: its first in its first interval, then its ping type's
    steps (``figures``: sbi's interval, rbi's bounds, pbi's sequence)."""
    if kind == "sbi":
        n = int(span / figures) + 2
        steps = figures + rng.normal(0, SBI_JITTER, n)
    elif kind == "rbi":
        n = int(span / figures[0]) + 2
        steps = rng.uniform(*figures, n)
    else:
        n = int(span / figures.min()) + 2
        steps = figures[np.arange(n) % len(figures)] + rng.normal(0, SBI_JITTER, n)
    times = rng.uniform(0, steps[0]) + np.r_[0.0, np.cumsum(steps[:-1])]
    return times[times < span]


def simulate_study(n_receivers: int = 20, n_tags: int = 100, days: float = 7.0, redeployed: int = 2, seed: int = 0,
                   spacing: float = 150.0, centre: tuple[float, float] = (60.38, 5.34),
                   start: str = "2024-06-03T00:00:00Z",
                   sound_speed: float | Callable[[np.ndarray], np.ndarray] = 1480.0,
                   sigma_toa: float | Sequence[float] = 0.15e-3,
                   range_50: float = 220.0, offset: float = 2.0, drift: float = 20e-6,
                   wander: float = 0.0) -> SimulatedStudy:
    """Simulate a study (the module docstring).

    Parameters
    ----------
    n_receivers : int
        Receivers (each with a sync tag), on a jittered grid ``spacing`` [m] apart.
    n_tags : int
        Animal tags, their ping types ``sbi``, ``rbi``, ``pbi`` in turn.
    days : float
        [d] the study's span.
    redeployed : int
        Receivers recovered in the middle third of the study and deployed again an hour later at another station.
    seed : int
        ``numpy.random.default_rng``'s seed.
    spacing, centre, start
        The grid's spacing [m], its centre (latitude, longitude [°]) and the study's start (ISO 8601 UTC).
    sound_speed, sigma_toa, range_50
        [m/s] (one, or a function of the emissions' true times (n,) [s from the start] giving each one's (n,)), the
        timing noise [s] (one, or each receiver's: ``n_receivers`` values, a redeployed receiver's the same at both
        its stations), the detection range curve's 50 % range [m].
    offset, drift, wander
        The clocks' offsets [s], drifts [s/s] and the amplitudes [s] of their wander about the line (a period of one
        to three days: the module docstring), uniform in ±.

    Returns
    -------
    SimulatedStudy
    """
    rng = np.random.default_rng(seed)
    origin = parse_instant(start, "start")
    span = days * 86400.0
    frame = Frame(utm_zone(*centre))
    cx, cy = frame.from_latlon(np.array([centre[0]]), np.array([centre[1]]))
    mid = np.array([cx[0], cy[0]])
    side = int(math.ceil(math.sqrt(n_receivers)))
    grid = np.array([(i, j) for j in range(side) for i in range(side)][:n_receivers], float)
    grid = (grid - grid.mean(axis=0)) * spacing + mid + rng.normal(0, spacing / 10, grid.shape)
    serials = [str(461000 + k) for k in range(n_receivers)]
    rows = [{"receiver": k, "x": grid[k, 0], "y": grid[k, 1], "start": 0.0, "end": span} for k in range(n_receivers)]
    moved = rng.choice(np.arange(1, n_receivers), size=min(redeployed, n_receivers - 1), replace=False)
    gap = min(3600.0, span / 10)  # out of the water an hour (less in a short study)
    for k in moved:
        out = rng.uniform(span / 3, 2 * span / 3)
        rows[k]["end"] = out
        shift = rng.normal(0, 1, 2)
        rows.append({"receiver": k, "x": grid[k, 0] + spacing / 2 * shift[0] / np.hypot(*shift),
                     "y": grid[k, 1] + spacing / 2 * shift[1] / np.hypot(*shift), "start": out + gap, "end": span})
    table = pd.DataFrame(rows)
    positions = table[["x", "y"]].to_numpy()
    if np.ndim(sigma_toa):  # each receiver's own timing noise, at each of its deployments
        given = np.asarray(sigma_toa, float)
        if given.shape != (n_receivers,):
            raise ValueError(f"simulate_study: {given.size} timing noises for {n_receivers} receivers")
        sigma_toa = given[table["receiver"].to_numpy()]
    clocks = pd.DataFrame({"deployment": np.arange(len(table)), "serial": [serials[k] for k in table["receiver"]],
                           "a": rng.uniform(-offset, offset, len(table)), "b": rng.uniform(-drift, drift, len(table)),
                           "start": table["start"], "end": table["end"]})
    if wander:  # (drawn only where asked: a study without wander draws what it drew before)
        clocks = clocks.assign(w=rng.uniform(-wander, wander, len(table)),
                               period=rng.uniform(86400.0, 3 * 86400.0, len(table)),
                               phase=rng.uniform(0.0, 2 * np.pi, len(table)))
    sync_ids = [f"{SYNC_SPACE}-{60000 + k}" for k in range(n_receivers)]
    lat, lon = frame.to_latlon(positions[:, 0], positions[:, 1])
    deployments = pd.DataFrame({
        "station": [f"ST{k + 1:02d}" + ("b" if j >= n_receivers else "") for j, k in enumerate(table["receiver"])],
        "ins_serial_no": clocks["serial"], "deploy_lat": lat, "deploy_long": lon,
        "deploy_date_time": iso_utc(origin + table["start"].to_numpy()),
        "recover_date_time": iso_utc(origin + table["end"].to_numpy()),
        "transmitter": [sync_ids[k] for k in table["receiver"]]})

    parts = []

    def heard(tau_e: np.ndarray, where: np.ndarray, transmitter: str, own: int | None = None) -> None:
        """The detections of emissions at ``tau_e`` (n,) from ``where`` (n, 2) by every deployment in the water."""
        d = np.linalg.norm(where[:, None, :] - positions[None], axis=2)
        c = sound_speed(tau_e)[:, None] if callable(sound_speed) else sound_speed
        arrival = tau_e[:, None] + d / c + rng.normal(0, sigma_toa, d.shape)
        p = 1 / (1 + np.exp((d - range_50) / (range_50 / 6)))
        if own is not None:
            p[:, own] = 0.9  # a receiver hears its own sync tag most of the time
        inside = (arrival >= table["start"].to_numpy()) & (arrival <= table["end"].to_numpy())
        e, j = np.nonzero((rng.random(d.shape) < p) & inside)
        parts.append(pd.DataFrame({"deployment": j, "transmitter": transmitter, "tau": arrival[e, j]}))

    for j, row in table.iterrows():  # each deployment's sync tag, emitting while it is in the water
        tau_e = _emissions("rbi", span, rng, SYNC_INTERVAL)
        tau_e = tau_e[(tau_e >= row["start"]) & (tau_e <= row["end"])]
        heard(tau_e, np.repeat(positions[j][None], len(tau_e), axis=0), sync_ids[int(row["receiver"])], j)
    for k in moved:  # on deck between the two deployments: the receiver logs its own sync tag
        first = table.index[(table["receiver"] == k)][0]
        tau = table.loc[first, "end"] + gap * np.linspace(0.15, 0.85, 5)
        parts.append(pd.DataFrame({"deployment": first, "transmitter": sync_ids[k], "tau": tau, "deck": True}))
    sheet, sequences, truth = [], {}, {}
    for k in range(n_tags):
        kind = ("sbi", "rbi", "pbi")[k % 3]
        ident = f"{ANIMAL_SPACE}-{1000 + k}"
        row = {"transmitter": ident, "ping_type": kind, "min_delay": "", "max_delay": "", "interval": "",
               "burst_sequence": "", "role": "animal"}
        if kind == "sbi":
            figures = float(np.round(rng.uniform(*SBI_RANGE)))
            row["interval"] = f"{figures:g}"
        elif kind == "rbi":
            figures = RBI_BOUNDS
            row["min_delay"], row["max_delay"] = f"{figures[0]:g}", f"{figures[1]:g}"
        else:
            figures = np.round(rng.uniform(*PBI_RANGE, 16), 1)
            row["burst_sequence"] = f"pbi_{1000 + k}.txt"
            sequences[row["burst_sequence"]] = figures
        tau_e = _emissions(kind, span, rng, figures)
        where = _path(rng, mid, spacing * (side - 1) / 2)(tau_e)
        heard(tau_e, where, ident)
        sheet.append(row)
        truth[ident] = pd.DataFrame({"tau": tau_e, "x": where[:, 0], "y": where[:, 1]})
    sheet += [{"transmitter": s, "ping_type": "rbi", "min_delay": "540", "max_delay": "660", "interval": "",
               "burst_sequence": "", "role": "sync"} for s in sync_ids]
    arrivals = pd.concat(parts, ignore_index=True)
    j = arrivals["deployment"].to_numpy()
    tau = arrivals["tau"].to_numpy()
    clock = origin + tau + clocks["a"].to_numpy()[j] + clocks["b"].to_numpy()[j] * tau + _wander(clocks, j, tau)
    detections = pd.DataFrame({"serial": clocks["serial"].to_numpy()[j], "model": "VR2AR",
                               "transmitter": arrivals["transmitter"].to_numpy(), "time": clock})
    detections = detections.sort_values(["serial", "time"], kind="stable").reset_index(drop=True)
    return SimulatedStudy(deployments, detections, pd.DataFrame(sheet), sequences, truth, clocks, frame, origin,
                          positions)


def _wander(clocks: pd.DataFrame, deployment: np.ndarray, tau: np.ndarray) -> np.ndarray | float:
    """[s] each deployment's clock's wander about its line (``clocks``' row ``deployment`` (n,)) at the true times
    ``tau`` (n,) [s]; 0 where none was simulated (added, it changes no time)."""
    if "w" not in clocks:
        return 0.0
    w, period, phase = (clocks[k].to_numpy()[deployment] for k in ("w", "period", "phase"))
    return w * np.sin(2 * np.pi * tau / period + phase)


__all__ = ["SimulatedStudy", "fathom_text", "glatos_text", "simulate_study", "vue_text"]
