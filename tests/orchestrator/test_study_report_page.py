"""A study's report (issue 100): ``report.html`` drawn from a study's folder, here a folder written by hand in the
layout ``sblsim track`` writes (invented values: four receivers, one of which stops logging on its second day while
still deployed, one not used; two tags tracked with flagged rows, two refused; a clock break; sync tags and
reference tags scored). Its figures' numbers are checked against tables built here from the same values (the
detections per day, the flagged rows by reason, the clock offsets less their trend, the reference tags' errors), the
page against the files (a row and a section per row of ``tags.csv``, every note said, every link's target there), and
the offline rule (no address in any ``src`` or ``href``, no script). A study whose tags are all refused gets a page
(``sblsim.track`` on one receiver), and ``sblsim report DIR`` writes the page again, refusing in one line a folder
that is not a study's, a hostile file and a ``report.html`` it did not write."""

from __future__ import annotations

import base64
import io
import json
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image

import sblsim
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.io.times import iso_utc
from sblsim.orchestrator.telemetry.report.daily import daily_counts
from sblsim.orchestrator.telemetry.report.decisions import decisions
from sblsim.orchestrator.telemetry.report.figures_study import clock_residuals, daily_matrix, reference_errors
from sblsim.orchestrator.telemetry.report.figures_tag import flag_counts
from sblsim.orchestrator.telemetry.report.folder import read_folder
from sblsim.orchestrator.telemetry.report.page import REPORT_FILE, render, write_report
from sblsim.orchestrator.telemetry.simulate import simulate_study, vue_text

DAY = 86400.0
T0 = 1_696_118_400.0  # 2023-10-01T00:00:00Z
RECEIVERS = ["R1", "R2", "R3", "R4"]
#: Each receiver's kept detections on days 0, 1, 2 (R4 stops logging after its first day, deployed to the end).
PER_DAY = {"R1": [120, 130, 90], "R2": [40, 0, 55], "R3": [10, 12, 8], "R4": [300, 0, 0]}
#: Each tracked tag's rows: quality and reason.
FLAGS = {"A-1": ["ok"] * 6 + [("flagged", "unverified"), ("flagged", "placed_less_well_than_a_fix;unverified"),
                              ("flagged", "")],
         "A-2": ["ok"] * 4 + [("flagged", "placed_less_well_than_a_fix"), "set_aside", "set_aside"]}
REFUSED = {"A-3": ("one_receiver", "heard by 1 receiver (R1, 40 detections): positioning needs 3 at once"),
           "A-4": ("never_detected", "tag: 'A-4' is never detected <script>alert(1)</script> inside a deployment")}
NOTES = ["receiver R2's clock broke at 2023-10-02T12:00:00Z: its clock split there", "the tag sheet's <b>A-9</b> is "
         "not detected"]
REFERENCE = [{"tag": "RT-1", "kind": "reference", "truth": "deployment R1", "receiver": "R1", "error_m": 1.25,
              "sigma_m": 0.8, "nees": 12.4, "beyond_sigma": True, "rows": 50, "flagged": 1,
              "receiver_persistent_m": None},
             {"tag": "802510", "kind": "sync_left_out", "truth": "its receiver R3's position", "receiver": "R3",
              "error_m": 0.61, "sigma_m": 0.9, "nees": 0.7, "beyond_sigma": False, "rows": 40, "flagged": 0,
              "receiver_persistent_m": None}]


def _tracks() -> pd.DataFrame:
    rows = []
    for k, (tag, qualities) in enumerate(FLAGS.items()):
        for j, q in enumerate(qualities):
            quality, reason = q if isinstance(q, tuple) else (q, "")
            t = T0 + 3600.0 * (j + 1) + 60 * k
            row = {"tag": tag, "time_utc": iso_utc([t])[0], "epoch_s": t, "lat": 55.0, "lon": 10.0,
                   "x": 500_000.0 + 10 * j, "y": 6_100_000.0 + 5 * j, "sigma_x": 0.5 + 0.1 * j, "sigma_y": 0.4,
                   "receivers_heard": 3 + j % 2, "quality": quality, "quality_reason": reason}
            if q == "set_aside":  # a row set aside as no ping of the tag's schedule: kept, with no estimate
                row |= {k: np.nan for k in ("epoch_s", "lat", "lon", "x", "y", "sigma_x", "sigma_y",
                                            "receivers_heard")} | {"time_utc": "", "quality": "flagged",
                                                                   "quality_reason": "set_aside_not_a_ping"}
            rows.append(row)
    return pd.DataFrame(rows)


def _tags() -> pd.DataFrame:
    rows = []
    tracks = _tracks()
    for tag in FLAGS:
        mine = tracks[tracks["tag"] == tag]
        aside = int((mine["quality_reason"] == "set_aside_not_a_ping").sum())
        rows.append({"tag": tag, "transmitter": tag, "name": "cod", "role": "animal", "motion": "moving",
                     "ping_type_stated": "inferred", "status": "tracked", "reason_code": "", "reason": "",
                     "detections": 40, "receivers": 3, "pings": len(mine), "pings_at_once": len(mine),
                     "positioned": len(mine) - aside, "set_aside": aside, "not_positioned": 0,
                     "not_positioned_why": "", "flagged": int((mine["quality"] == "flagged").sum()) - aside,
                     "median_sigma_m": 0.7, "ping_type": "rbi",
                     "track": "robust", "sound_speed_m_s": 1476.2,
                     "sound_speed_source": "calibrated" if tag == "A-1" else "fallback",
                     "first_utc": mine["time_utc"].iloc[0], "last_utc": mine["time_utc"].iloc[-1],
                     "folder": f"tags/{tag}"})
    for tag, (code, reason) in REFUSED.items():
        rows.append({"tag": tag if code != "never_detected" else "", "transmitter": tag, "name": "",
                     "role": "animal", "motion": "moving", "ping_type_stated": "inferred", "status": "refused",
                     "reason_code": code, "reason": reason, "detections": 40 if code == "one_receiver" else None,
                     "pings": 0, "positioned": 0, "set_aside": 0, "not_positioned": 0, "flagged": 0})
    return pd.DataFrame(rows)


def _offsets() -> pd.DataFrame:
    """Hourly bins over two days: R1 the reference (0), R2 with a break at 36 h (two segments), R3 and R4 drifting
    with a wobble."""
    rows = []
    edges = T0 + 3600.0 * np.arange(49)
    for name in RECEIVERS:
        value = {"R1": 0 * edges, "R2": 1e-6 * (edges - T0) + 2e-4 * np.sin((edges - T0) / 7e3),
                 "R3": 0.5 - 3e-6 * (edges - T0) + 1e-4 * np.cos((edges - T0) / 5e3),
                 "R4": -2.0 + 2e-6 * (edges - T0)}[name]
        for b in range(48):
            segment = 1 if name != "R2" or b < 36 else 2
            rows.append({"receiver": name, "bin": b, "start": edges[b], "end": edges[b + 1],
                         "offset_start_s": value[b] + (0.01 if segment == 2 else 0.0),
                         "offset_start_sigma_s": 2e-4, "offset_end_s": value[b + 1] + (0.01 if segment == 2 else 0.0),
                         "offset_end_sigma_s": 2e-4, "toa_sigma_s": 1e-3, "clock_sigma_s": 0.0 if name == "R1"
                         else 3e-4, "segment": segment})
    return pd.DataFrame(rows)


def _summary() -> dict:
    return {"detections": {"file": "detections.csv", "format": "vue", "rows": 1000, "used": 765, "set_aside": 235,
                           "reasons": {"receiver_not_in_table": 35, "outside_deployment": 200,
                                       "sync_tag_outside_deployment": 0, "per_serial": {"999": 35}},
                           "first_utc": iso_utc([T0])[0], "last_utc": iso_utc([T0 + 3 * DAY - 1])[0]},
            "receivers": {"file": "deployments.csv", "deployments": 4, "receivers": 4, "in_sheet": 5, "used": 4,
                          "not_used": {"count": 1, "serial_never_detected": 1}, "notes": ["2 deployments open"]},
            "frame": {"crs": "EPSG:32632", "name": "WGS 84 / UTM zone 32N", "chosen": "the UTM zone of the array's "
                      "centre", "scale_factor": 0.9996},
            "clocks": {"source": "synchronised here", "reference_receiver": "R1", "receivers": 4, "bin_hours": 1.0,
                       "not_synchronised": [], "clock_breaks": [{"receiver": "R2", "time_s": T0 + 36 * 3600.0,
                                                                 "time_utc": iso_utc([T0 + 36 * 3600.0])[0],
                                                                 "size_s": 0.01, "size_sigma_s": 1e-4,
                                                                 "segment_before": 1, "segment_after": 2,
                                                                 "synchronised": True}]},
            "tag_sheet": {"file": "tags.csv", "transmitters": 6}, "notes": NOTES,
            "toa_noise": {"source": "synchronisation", "sigma_s": 1e-3,
                          "per_receiver_s": {n: 1e-3 * (k + 1) for k, n in enumerate(RECEIVERS)}},
            "reference_tags": {"tags": REFERENCE, "reference": {"tags": 1, "median_error_m": 1.25, "nees_mean": 12.4,
                                                                "nees_consistent_90": [0.1, 4.6], "survey_stated": 0,
                                                                "rows": 50, "flagged": 1, "beyond_nees": 9.21},
                               "sync_left_out": None, "array_persistent_m": None, "notes": [],
                               "not_scored": [{"tag": "RT-2", "why": "no surveyed position"}]}}


def write_folder(out: Path) -> Path:
    """A study's folder as ``sblsim track`` writes it (the module docstring), in ``out``."""
    (out / "sync").mkdir(parents=True)
    (out / "study.json").write_text(json.dumps(_summary(), indent=2))
    _tags().to_csv(out / "tags.csv", index=False)
    _tracks().to_csv(out / "tracks.csv", index=False)
    pd.DataFrame({"receiver": RECEIVERS + ["R9"], "serial": ["1", "2", "3", "4", "9"],
                  "x_m": [500_000.0, 500_100, 500_000, 500_100, 0],
                  "y_m": [6_100_000.0, 6_100_000, 6_100_100, 6_100_100, 0],
                  "lat": [55.0, 55.0, 55.001, 55.001, 40.0], "lon": [10.0, 10.001, 10.0, 10.001, -70.0],
                  "start_utc": iso_utc([T0] * 4 + [T0 - 400 * DAY]),
                  "end_utc": ["", "", "", "", iso_utc([T0 - 300 * DAY])[0]],
                  "used": [True] * 4 + [False], "not_used": [""] * 4 + ["serial_never_detected"],
                  "detections": [sum(PER_DAY[n]) for n in RECEIVERS] + [0]}).to_csv(out / "receivers.csv",
                                                                                   index=False)
    pd.DataFrame([{"receiver": n, "day": iso_utc([T0 + d * DAY])[0][:10], "detections": c}
                  for n in RECEIVERS for d, c in enumerate(PER_DAY[n]) if c]).to_csv(out / "detections_daily.csv",
                                                                                     index=False)
    _offsets().to_csv(out / "sync" / "offsets.csv", index=False)
    pd.DataFrame({"tag": ["802510", "802511"], "receiver": ["R3", "R4"], "fixes": [40, 38],
                  "median_error_m": [0.61, 2.2], "p90_error_m": [1.1, 4.0], "median_sigma_m": [0.9, 1.0],
                  "nees_mean": [0.7, 3.1], "leave_one_out": [True, True]}).to_csv(out / "sync" / "sync_tags.csv",
                                                                                    index=False)
    pd.DataFrame(REFERENCE).to_csv(out / "reference_tags.csv", index=False)
    for tag in FLAGS:
        (out / "tags" / tag).mkdir(parents=True)
        (out / "tags" / tag / "summary.json").write_text(json.dumps({
            "sound_speed": {"sound_speed_m_s": 1476.2, "source": "calibrated", "method": "a fit", "sigma_m_s": 1.5},
            "ping_type": {"type": "rbi", "burst_interval_s": [60.0, 120.0]}, "depth": {"source": "none (2-D)"}}))
    picture = io.BytesIO()
    Image.new("RGB", (40, 30), (200, 30, 30)).save(picture, format="PNG")
    (out / "map.png").write_bytes(picture.getvalue())
    return out


@pytest.fixture()
def folder(tmp_path) -> Path:
    return write_folder(tmp_path / "study")


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """The hand-written study's folder, as read, and its page (rendered once for the tests that only read them)."""
    out = write_folder(tmp_path_factory.mktemp("page") / "study")
    study = read_folder(out)
    return out, study, render(study)


class _Page(HTMLParser):
    """The page's elements as the tests read them: every element's attributes, the ids, the tag table's rows."""

    def __init__(self) -> None:
        super().__init__()
        self.elements: list[tuple[str, dict[str, str]]] = []
        self.ids: set[str] = set()
        self.table_rows: list[list[str]] = []
        self._in_table = False
        self._row: list[str] | None = None
        self._text = ""

    def handle_starttag(self, tag, attrs):
        attributes = {k: v or "" for k, v in attrs}
        self.elements.append((tag, attributes))
        if "id" in attributes:
            self.ids.add(attributes["id"])
        if tag == "table" and attributes.get("id") == "tag-table":
            self._in_table = True
        elif self._in_table and tag == "tr":
            self._row = []
        elif self._row is not None and tag == "td":
            self._text = ""

    def handle_endtag(self, tag):
        if tag == "table":
            self._in_table = False
        elif tag == "td" and self._row is not None:
            self._row.append(self._text.strip())
        elif tag == "tr" and self._row is not None:
            if self._row:  # the header row has no cells
                self.table_rows.append(self._row)
            self._row = None

    def handle_data(self, data):
        self._text += data


def _parsed(text: str) -> _Page:
    page = _Page()
    page.feed(text)
    return page


def test_the_page_has_a_row_and_a_section_per_tag_and_every_link_s_target(rendered):
    folder, _, text = rendered
    page = _parsed(text)
    tags = pd.read_csv(folder / "tags.csv", keep_default_na=False)
    shown = [t or tr for t, tr in zip(tags["tag"].astype(str), tags["transmitter"].astype(str))]
    assert [row[0] for row in page.table_rows] == shown
    assert [row[3] for row in page.table_rows] == tags["status"].tolist()  # tag, name, role, status
    links = [a["href"][1:] for tag, a in page.elements if tag == "a" and a.get("href", "").startswith("#")]
    assert len(links) >= len(tags) + 4 and set(links) <= page.ids
    for code, reason in REFUSED.values():
        assert code in text
        assert reason.replace("'", "&#39;").replace("<", "&lt;").replace(">", "&gt;") in text  # escaped, whole
    assert "<script>" not in text and "<b>A-9</b>" not in text
    for note in NOTES:
        assert note.replace("'", "&#39;").replace("<", "&lt;").replace(">", "&gt;") in text
    assert "reference tag RT-2 not scored: no surveyed position" in text  # the console's lines
    assert "reference tag RT-1 is 1.25 m from deployment R1, NEES 12.4 beyond its σ of 0.8 m" in text


def test_the_detections_per_day_are_the_receivers_counts(rendered):
    names, days, counts, deployed = daily_matrix(rendered[1])
    assert names == RECEIVERS
    assert days == [iso_utc([T0 + d * DAY])[0][:10] for d in range(3)]
    assert np.array_equal(counts, np.array([PER_DAY[n] for n in RECEIVERS], float))
    assert deployed.all()  # open deployments: R4's days without a detection are deployed and silent
    assert counts.sum(axis=1).tolist() == [sum(PER_DAY[n]) for n in RECEIVERS]  # receivers.csv's detections


def test_daily_counts_count_each_receiver_s_detections_by_utc_day():
    rng = np.random.default_rng(3)
    times = T0 + rng.uniform(-0.5 * DAY, 2.5 * DAY, 500)
    receivers = rng.choice(["a", "b.1", "b.2"], 500)
    counts = daily_counts(pd.DataFrame({"receiver": receivers, "time": times}))
    expected: dict[tuple[str, str], int] = {}
    for name, t in zip(receivers, times):
        day = iso_utc([np.floor(t / DAY) * DAY])[0][:10]
        expected[(name, day)] = expected.get((name, day), 0) + 1
    assert dict(zip(zip(counts["receiver"], counts["day"]), counts["detections"])) == expected
    assert counts["detections"].sum() == 500


def test_the_flagged_rows_are_counted_by_each_of_their_reasons(rendered):
    study = rendered[1]
    for tag, qualities in FLAGS.items():
        expected: dict[str, int] = {}
        for q in qualities:
            if isinstance(q, tuple):
                for reason in (q[1].split(";") if q[1] else ["(no reason given)"]):
                    expected[reason] = expected.get(reason, 0) + 1
        assert flag_counts(study, tag) == expected  # the rows set aside (no position) not among them
    tags = pd.read_csv(rendered[0] / "tags.csv").set_index("tag")
    assert tags.loc["A-2", "set_aside"] == 2
    for tag in FLAGS:  # each flagged row counted once among tags.csv's flagged, whatever its reasons
        rows = study.tracks[(study.tracks["tag"] == tag) & study.tracks["x"].notna()]
        assert (rows["quality"] == "flagged").sum() == tags.loc[tag, "flagged"]


def test_the_clock_offsets_less_their_trend(rendered):
    offsets = _offsets()
    found = clock_residuals(rendered[1].offsets)
    assert set(found) == set(RECEIVERS) and len(found["R2"]) == 2 and len(found["R1"]) == 1
    for name, parts in found.items():
        for k, part in enumerate(parts):
            rows = offsets[(offsets["receiver"] == name) & (offsets["segment"] == k + 1)]
            t = np.r_[rows["start"], rows["end"].iloc[-1]]
            value = np.r_[rows["offset_start_s"], rows["offset_end_s"].iloc[-1]]
            assert np.array_equal(part["time"], t)
            trend = value - part["residual_ms"] / 1e3  # what was taken away: a line in time
            design = np.c_[np.ones_like(t), t - t[0]]
            assert np.allclose(np.diff(trend, 2), 0, atol=1e-9)
            assert np.allclose(design.T @ part["residual_ms"], 0, atol=1e-6 * len(t) * (t[-1] - t[0]))
            assert np.allclose(part["band_ms"], 2 * 0.2)
    assert np.max(np.abs(found["R4"][0]["residual_ms"])) < 1e-6  # a straight drift leaves nothing


def test_the_reference_tags_errors_are_those_of_reference_tags_csv(rendered):
    _, study, text = rendered
    drawn = reference_errors(study)
    table = pd.DataFrame(REFERENCE).sort_values("error_m")
    assert drawn["tag"].tolist() == table["tag"].astype(str).tolist()
    assert np.array_equal(drawn["error"], table["error_m"]) and np.array_equal(drawn["sigma"], table["sigma_m"])
    page = _parsed(text)
    assert "The reference tags" in text and 'id="reference-tags"' in text
    for row in REFERENCE:
        assert f"<td>{row['tag']}</td>" in text and f"<td>{row['nees']:g}</td>" in text
    assert any(a.get("alt", "").startswith("the errors of 2 reference tags") for _, a in page.elements)


def test_the_page_names_no_address_and_runs_no_script(rendered):
    text = rendered[2]
    page = _parsed(text)
    kinds = {tag for tag, _ in page.elements}
    assert not kinds & {"script", "link", "iframe", "object", "embed", "base"}
    images = [a["src"] for tag, a in page.elements if tag == "img"]
    assert len(images) >= 6  # the map, the days, the clocks, the noise, the sync tags, two tags, the reference tags
    for source in images:
        assert source.startswith("data:image/png;base64,")
        picture = Image.open(io.BytesIO(base64.b64decode(source.split(",", 1)[1])))
        assert picture.width > 100 or picture.size == (40, 30)
    for tag, attributes in page.elements:
        for key in ("src", "href", "srcset", "action", "poster", "data"):
            value = attributes.get(key, "")
            assert not re.match(r"\s*(https?:|//|ftp:|file:)", value, re.I), (tag, key, value)
    assert not re.search(r"url\(|@import", text)


def test_every_note_and_default_taken_is_said_with_its_option(rendered):
    _, study, text = rendered
    rows = {d["what"]: d for d in decisions(study)}
    assert rows["sound speed"]["taken"] == "calibrated: 1 tag; fallback: 1 tag"
    assert "--sound-speed" in rows["sound speed"]["option"]
    assert rows["timing noise (TOA σ)"]["option"] == "--toa-sigma S"
    assert rows["frame"]["how"].endswith("(the default)") and "--frame" in rows["frame"]["option"]
    assert rows["ping type"]["taken"] == "rbi: 2 tags"
    assert "2 deployments open" in text  # the receivers file's note
    assert "A-2: the pings do not determine the sound speed (fallback)" in text  # the console's warning


def refused_study(tmp: Path) -> tuple[Path, pd.DataFrame]:
    """One receiver of a simulated study, tracked by sblsim.track into ``tmp/study``: every tag refused (heard by one
    receiver); the folder and ``tags.csv``."""
    sim = simulate_study(n_receivers=9, n_tags=3, days=0.1, redeployed=0, seed=3)
    files = sim.write(tmp / "in", "vue")
    serial = sim.deployments["ins_serial_no"].iloc[4]
    sim.deployments[sim.deployments["ins_serial_no"] == serial].to_csv(files["deployments"], index=False,
                                                                       float_format="%.10f")
    files["detections"].write_text(vue_text(sim.detections[sim.detections["serial"] == serial]
                                            .reset_index(drop=True)))
    result = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"], workers=1,
                          out=tmp / "study")
    return tmp / "study", result.tags


@pytest.fixture(scope="module")
def refused(tmp_path_factory) -> tuple[Path, pd.DataFrame]:
    return refused_study(tmp_path_factory.mktemp("refused"))


def test_a_study_whose_tags_are_all_refused_has_its_page(refused):
    out, tags = refused
    assert (tags["status"] == "refused").all() and len(tags) == 3
    text = (out / REPORT_FILE).read_text()
    page = _parsed(text)
    assert [row[0] for row in page.table_rows] == tags["tag"].astype(str).tolist()
    assert f"<td>one_receiver</td><td>{len(tags)}</td>" in text.replace("\n", "")
    for reason in tags["reason"]:
        assert reason in text
    assert (out / "detections_daily.csv").exists()
    daily = pd.read_csv(out / "detections_daily.csv", dtype={"receiver": str})
    assert daily["detections"].sum() == pd.read_csv(out / "receivers.csv")["detections"].sum()


@pytest.mark.slow
def test_sblsim_report_writes_the_page_again_and_refuses_in_one_line(folder, tmp_path, capsys):
    assert main(["report", str(folder)]) == 0
    assert capsys.readouterr().out.startswith(f"wrote {folder / REPORT_FILE}")
    first = (folder / REPORT_FILE).read_text()
    assert 'id="tag-table"' in first
    assert main(["report", str(folder)]) == 0  # its own page replaced
    (folder / REPORT_FILE).write_text("mine")  # a file sblsim did not write (edited since)
    assert main(["report", str(folder)]) == 2
    assert "report.html" in capsys.readouterr().err and (folder / REPORT_FILE).read_text() == "mine"
    assert main(["report", str(tmp_path / "nothing")]) == 2
    assert "is not a folder" in capsys.readouterr().err


@pytest.mark.parametrize("edit, said", [
    (lambda f: (f / "study.json").unlink(), "holds no study.json"),
    (lambda f: (f / "tags.csv").write_text((f / "tags.csv").read_text().replace(",40.0,3.0,", ",forty,3.0,", 1)),
     "tags.csv' line 2 column detections: 'forty' is not allowed"),
    (lambda f: (f / "study.json").write_text("[1, 2]"), "holds no JSON object"),
    (lambda f: (f / "study.json").write_text('{"clocks": "synchronised"}'), "not a study as sblsim track writes"),
])
def test_a_folder_that_is_not_a_study_s_is_refused_in_one_line(folder, edit, said):
    edit(folder)
    with pytest.raises(ModelError, match=re.escape(said)) as found:
        write_report(folder)
    assert "\n" not in str(found.value) and not (folder / REPORT_FILE).exists()


def test_a_file_that_leads_out_of_the_folder_is_refused(folder, tmp_path):
    secret = tmp_path / "elsewhere.csv"
    secret.write_text((folder / "tracks.csv").read_text())
    (folder / "tracks.csv").unlink()
    (folder / "tracks.csv").symlink_to(secret)
    with pytest.raises(ModelError, match="outside the folder"):
        write_report(folder)


@pytest.mark.slow
def test_the_tags_drawn_are_capped_at_those_with_the_most_rows(rendered, monkeypatch):
    from sblsim.orchestrator.telemetry.report import context

    monkeypatch.setattr(context, "MAX_TAG_FIGURES", 1)
    text = render(rendered[1])
    drawn = re.findall(r'alt="tag ([^ ]+)\'s track', text.replace("&#39;", "'"))
    assert drawn == ["A-1"]  # 9 rows positioned against A-2's 5
    section = text[text.index('id="tag-2-A-2"'):text.index('id="tag-3-A-3"')]
    assert "Not drawn here: the page draws the 1 tags with the most rows" in section.replace("\n", " ")
