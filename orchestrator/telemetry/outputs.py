"""A study's files (:func:`write_study`), for R, QGIS and a reader: ``tracks.csv`` (every tag's rows: ``tag``,
``time_utc``, ``epoch_s``, ``lat``, ``lon``, ``x``, ``y``, ``sigma_x``, ``sigma_y``, ``quality``, ...), ``tags.csv``
(a row per tag), ``receivers.csv`` (the deployments in the frame and in latitude and longitude), ``study.json`` (the
summary: the files, the frame and its CRS, the detections set aside, the clocks, the tags),
``tracks.geojson`` (RFC 7946: the receivers as points, each tag's rows not flagged as a line, WGS 84 longitude and
latitude; where the frame is known), ``map.png`` (every track over the receivers, a scale bar), the
synchronisation made (``sync/``, as ``sblsim sync`` writes it) and one folder per tag (its ``toa.txt``,
``receivers.csv``, ``pings.csv``, ``toa.json`` and its track's files as ``sblsim replay`` writes them).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from sblsim.orchestrator.sync.outputs import plain
from sblsim.orchestrator.sync.outputs import write as write_sync
from sblsim.orchestrator.telemetry.study import StudyOutcome
from sblsim.orchestrator.tracks.outputs import scale_bar, write


def geojson(outcome: StudyOutcome) -> dict[str, Any] | None:
    """The receivers and the tracks as a GeoJSON FeatureCollection (RFC 7946: WGS 84 longitude, latitude); None
    where the positions have no CRS."""
    table = outcome.deployments.written()
    if outcome.deployments.frame is None or not np.isfinite(table["lat"].to_numpy(float)).all():
        return None
    features = []
    for row in table.itertuples(index=False):
        features.append({"type": "Feature", "geometry": {"type": "Point", "coordinates": [row.lon, row.lat]},
                         "properties": {"kind": "receiver", "receiver": row.receiver, "serial": row.serial,
                                        "station": row.station, "sync_tag": row.sync_tag,
                                        "start_utc": row.start_utc, "end_utc": row.end_utc}})
    for tag, rows in outcome.tracks.groupby("tag", sort=False):
        ok = rows[(rows["quality"] != "flagged") & rows["lat"].notna()]
        if len(ok) < 2:
            continue
        features.append({"type": "Feature",
                         "geometry": {"type": "LineString",
                                      "coordinates": np.c_[ok["lon"].to_numpy(float), ok["lat"].to_numpy(float)]
                                      .round(8).tolist()},
                         "properties": {"kind": "track", "tag": tag, "rows": int(len(ok)),
                                        "flagged_rows_left_out": int((rows["quality"] == "flagged").sum()),
                                        "first_utc": ok["time_utc"].iloc[0], "last_utc": ok["time_utc"].iloc[-1]}})
    return {"type": "FeatureCollection", "features": plain(features)}


def study_map(outcome: StudyOutcome):
    """Every tag's track (the rows not flagged) over the receivers in the frame, with a scale bar (matplotlib)."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 8))
    table = outcome.deployments.table
    ax.plot(table["x"], table["y"], "^", color="k", ms=7, label="receivers", zorder=3)
    for name, x, y in table[["receiver", "x", "y"]].itertuples(index=False):
        ax.annotate(name, (x, y), fontsize=6, xytext=(3, 3), textcoords="offset points")
    colours = plt.get_cmap("tab10").colors
    tags = list(outcome.tracks.groupby("tag", sort=False))
    for k, (tag, rows) in enumerate(tags):
        ok = rows[rows["quality"] != "flagged"]
        ax.plot(ok["x"], ok["y"], ".-", ms=2, lw=0.4, color=colours[k % len(colours)], alpha=0.8,
                label=f"{tag} ({len(ok)} of {len(rows)} rows)" if len(tags) <= 20 else None)
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.set(aspect="equal", xlabel="x (east) [m]", ylabel="y (north) [m]")
    frame = outcome.summary.get("frame")
    ax.set_title(f"{len(tags)} tags tracked (rows not flagged)" + (f"; {frame['name']} ({frame['crs']})" if frame
                                                                     else "; a local frame without a CRS"), fontsize=9)
    x = np.r_[table["x"].to_numpy(float), outcome.tracks["x"].to_numpy(float)]
    y = np.r_[table["y"].to_numpy(float), outcome.tracks["y"].to_numpy(float)]
    ok = np.isfinite(x) & np.isfinite(y)
    scale_bar(ax, max(np.ptp(x[ok]), np.ptp(y[ok])) if ok.any() else float("nan"))
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    return fig


def write_study(outcome: StudyOutcome, folder: Path) -> None:
    """The study's files (the module docstring) into ``folder`` (the tags' folders are there already, with their
    matrices): each tracked tag's track files, the synchronisation made, then the study's own files."""
    import matplotlib.pyplot as plt

    for name, tag in outcome.outcomes.items():
        write(tag, folder / name)
    if outcome.sync is not None:
        write_sync(outcome.sync, folder / "sync")
    outcome.tracks.to_csv(folder / "tracks.csv", index=False)
    outcome.tags.to_csv(folder / "tags.csv", index=False)
    outcome.deployments.written().to_csv(folder / "receivers.csv", index=False)
    (folder / "study.json").write_text(json.dumps(plain(outcome.summary), indent=2, allow_nan=False) + "\n")
    shapes = geojson(outcome)
    if shapes is not None:
        (folder / "tracks.geojson").write_text(json.dumps(shapes, allow_nan=False) + "\n")
    fig = study_map(outcome)
    try:
        fig.savefig(folder / "map.png", dpi=110)
    finally:
        plt.close(fig)


__all__ = ["geojson", "study_map", "write_study"]
