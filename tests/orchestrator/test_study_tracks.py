"""``tracks.csv`` a tag at a time from the tags' own ``track.csv`` files (orchestrator/telemetry/study_tracks.py
``TrackParts``) is byte for byte the table made whole by pandas (``combined_tracks``, then ``to_csv``): tags whose
columns differ in type (a count with and without empty cells, a reason empty or missing, a 3-D tag beside 2-D ones),
rows out of time order and rows without a time, tag names whose order is not the order they ended in."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd

from sblsim.orchestrator.io.times import iso_utc
from sblsim.orchestrator.telemetry.study_tracks import TRACK_COLUMNS, TrackParts, combined_tracks, tag_tracks


def _track(rng, n: int, aside: int = 0, three_d: bool = False, reason=np.nan) -> pd.DataFrame:
    """A tag's track as the tracker returns it (its own extra column ``time`` first), ``aside`` rows without a
    position or a time (quality flagged), shuffled in time."""
    epoch = 1.7e9 + np.sort(rng.uniform(0, 86400, n))
    track = pd.DataFrame({"time": epoch - 1.7e9, "epoch_s": epoch, "time_utc": iso_utc(epoch),
                          "x": rng.normal(3e5, 40, n), "y": rng.normal(6.7e6, 40, n),
                          "lat": rng.normal(60.3, 1e-3, n), "lon": rng.normal(5.3, 1e-3, n),
                          "sigma_x": rng.uniform(0.1, 3, n), "sigma_y": rng.uniform(0.1, 3, n),
                          "receivers_heard": rng.integers(3, 9, n),
                          "quality": np.where(rng.random(n) < 0.2, "flagged", "ok"), "quality_reason": reason})
    if three_d:
        track.insert(5, "z", rng.normal(-20, 2, n))
        track.insert(9, "sigma_z", rng.uniform(0.5, 4, n))
    if aside:
        lost = rng.choice(n, aside, replace=False)
        track.loc[lost, ["epoch_s", "x", "y", "lat", "lon", "sigma_x", "sigma_y", "receivers_heard"]] = np.nan
        track.loc[lost, ["time_utc", "quality", "quality_reason"]] = ["", "flagged", "set_aside_not_a_ping"]
    return track.sample(frac=1.0, random_state=int(rng.integers(1000))).reset_index(drop=True)


def _tracks(rng, three_d: bool) -> dict[str, pd.DataFrame]:
    return {"T-9": _track(rng, 40), "T-10": _track(rng, 55, aside=4, reason=""), "A 1": _track(rng, 30, reason="ok"),
            "b": _track(rng, 25, three_d=three_d), "T-2": _track(rng, 1)}


def _parts(tmp_path, tracks: dict[str, pd.DataFrame]) -> TrackParts:
    parts = TrackParts(tmp_path)
    for k, (tag, track) in enumerate(tracks.items()):
        folder = tmp_path / "tags" / f"t{k}"
        folder.mkdir(parents=True)
        track.to_csv(folder / "track.csv", index=False)  # as the tag's own files are written
        parts.add(tag, f"tags/t{k}", track)
    return parts


def test_a_tag_at_a_time_is_the_whole_table_byte_for_byte(tmp_path):
    rng = np.random.default_rng(11)
    for three_d in (False, True):
        tracks = _tracks(rng, three_d)
        folder = tmp_path / f"three_d_{three_d}"
        parts = _parts(folder, tracks)
        outcomes = {f"f{k}": SimpleNamespace(track=t) for k, t in enumerate(tracks.values())}
        matrices = {f"f{k}": SimpleNamespace(summary={"tag": tag}) for k, tag in enumerate(tracks)}
        whole = combined_tracks(outcomes, matrices)
        parts.write(folder / "tracks.csv")
        assert (folder / "tracks.csv").read_text() == whole.to_csv(index=False)
        assert ("z" in whole) == three_d and whole["receivers_heard"].dtype == float  # a count beside empty cells
        got = [tag for tag, _ in tag_tracks(None, parts)]
        assert got == sorted(tracks) == [tag for tag, _ in tag_tracks(whole, None)]
        for (_, rows), (_, mine) in zip(tag_tracks(whole, None), tag_tracks(None, parts)):  # as the map draws them
            assert mine.to_csv(index=False) == rows.to_csv(index=False)
            np.testing.assert_array_equal(mine[["x", "y", "lat", "lon"]].to_numpy(float),
                                          rows[["x", "y", "lat", "lon"]].to_numpy(float))


def test_no_tag_writes_the_header_alone(tmp_path):
    TrackParts(tmp_path).write(tmp_path / "tracks.csv")
    assert (tmp_path / "tracks.csv").read_text() == ",".join(TRACK_COLUMNS) + "\n"


def test_what_else_is_made_of_the_rows_comes_from_the_one_reading(tmp_path, monkeypatch):
    """``TrackParts.write(path, each)``: ``each`` sees every tag's rows as ``tracks.csv`` holds them, in its order,
    and each tag's own ``track.csv`` is read once (the GeoJSON's lines and the map's tracks made from that reading,
    orchestrator/telemetry/outputs.py)."""
    tracks = _tracks(np.random.default_rng(12), False)
    parts = _parts(tmp_path, tracks)
    reads: list = []
    read_csv = pd.read_csv
    monkeypatch.setattr(pd, "read_csv", lambda path, *a, **k: reads.append(path) or read_csv(path, *a, **k))
    seen: list = []
    parts.write(tmp_path / "tracks.csv", lambda tag, rows: seen.append((tag, rows.to_csv(index=False))))
    assert sorted(reads) == sorted(tmp_path / "tags" / f"t{k}" / "track.csv" for k in range(len(tracks)))
    monkeypatch.setattr(pd, "read_csv", read_csv)
    assert [tag for tag, _ in seen] == sorted(tracks)
    whole = combined_tracks({f"f{k}": SimpleNamespace(track=t) for k, t in enumerate(tracks.values())},
                            {f"f{k}": SimpleNamespace(summary={"tag": tag}) for k, tag in enumerate(tracks)})
    assert [text for _, text in seen] == [rows.to_csv(index=False) for _, rows in tag_tracks(whole, None)]
