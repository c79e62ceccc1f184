"""The receivers' own temperature records as the tracker's temperature series (issue 87, item 5): a Fathom (VDAT) CSV's
TEMP, TEMP_STATS and DIAG records (formats 1.0.0 and 2.0.0, interleaved with detections) and a VUE receiver-events
export (Latin-1 ``°C``), two receivers averaged; the series against one computed here from the records as they were
written (numpy's interpolation and mean); bad records refused in one line; and a simulated study tracked with its own
Fathom export as the temperature file, its sound speed TEOS-10's at the records' 9.5 °C (gsw here)."""

from __future__ import annotations

import csv
import io

import gsw
import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.water import read_temperature_series
from sblsim.orchestrator.telemetry.simulate import simulate_study
from tests.helpers import check_tag_rows

ORIGIN = pd.Timestamp("2021-04-20T17:00:00Z").timestamp()
HEAD = ["Device Time (UTC)", "Time", "Time Offset (h)", "Time Correction (s)", "Model", "Serial Number"]
DET = {"1.0.0": HEAD + ["Detection Type", "Full ID", "ID", "Signal Strength (dB)", "Noise (dB)", "Quality Score",
                        "Decoder", "Sensor Value", "Sensor Unit"],
       "2.0.0": HEAD + ["Channel", "Detection Type", "Full ID", "ID", "Raw Data", "Transmitter Serial",
                        "Signal Strength (dB)", "Noise (dB)", "Gain (dB)", "Quality Score", "Station Name",
                        "Latitude", "Longitude", "GPS HDOP"]}
TEMP = HEAD + ["Ambient (deg C)", "Internal (deg C)"]
TEMP_STATS = HEAD + ["Ambient Min (deg C)", "Ambient Max (deg C)", "Ambient Mean (deg C)", "Sample Count",
                     "Accumulation Period (s)"]
DIAG = HEAD + ["Ambient Temperature (deg C)", "Noise Mean (mV)", "Tilt (deg)", "Depth (m)", "PPM Pings",
               "PPM Detections"]
#: The records written: (record type, receiver, seconds after ORIGIN, water temperature [°C]); the receiver's
#: internal temperature is 30 °C throughout (never to be taken).
RECORDS = [("TEMP", "461396", 0.0, 10.0), ("TEMP", "461397", 300.0, 13.0), ("TEMP", "461396", 600.0, 10.5),
           ("TEMP_STATS", "461396", 900.0, 10.75), ("TEMP", "461396", 1200.0, 11.0),
           ("DIAG", "461397", 1500.0, 13.5), ("DIAG", "461396", 1500.0, 12.0), ("TEMP_STATS", "461397", 2400.0, 14.0)]


def _utc(seconds: float) -> str:
    return (pd.Timestamp(ORIGIN + seconds, unit="s", tz="UTC")).strftime("%Y-%m-%d %H:%M:%S.%f")


def _head(seconds: float, serial: str, corrected: str | None = None) -> list[str]:
    """The common columns: the device's clock 4 s behind, ``Time`` (Fathom's corrected UTC) the true time (or
    ``corrected`` as given)."""
    return [_utc(seconds - 4.0), _utc(seconds) if corrected is None else corrected, "+0", "4", "VR2AR", serial]


def _fathom(version: str = "2.0.0", records=RECORDS, temp=TEMP, empty_time: int | None = None) -> str:
    """A Fathom CSV: its first line, the record-type line, each type's _DESC line, then detections and the
    temperature records interleaved; record ``empty_time`` with an empty ``Time`` (its Device Time then taken:
    written as the true time)."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    out.write(f"VEMCO DATA LOG,{version},vdat-9.3.0\n")
    w.writerow(["RECORD TYPE"] + ["FIELD"] * len(DET[version]))
    for name, columns in (("DET", DET[version]), ("TEMP", temp), ("TEMP_STATS", TEMP_STATS), ("DIAG", DIAG)):
        w.writerow([f"{name}_DESC"] + columns)
    for k, (record, serial, t, value) in enumerate(records):
        det = _head(t - 1.0, serial) + ["A69-1602-4555" if c == "Full ID" else "" for c in DET[version][6:]]
        w.writerow(["DET"] + det)
        head = _head(t, serial) if k != empty_time else [_utc(t), "", "+0", "", "VR2AR", serial]
        own = {"TEMP": [value, 30.0], "TEMP_STATS": [value - 0.5, value + 0.5, value, 60, 600],
               "DIAG": [value, 120, 1.0, 5.0, 10, 9]}[record]
        w.writerow([record] + head + own)
    return out.getvalue()


def _expected(records=RECORDS) -> np.ndarray:
    """The array's mean computed here: each receiver's records interpolated at every record's time (held at its
    ends), averaged over the receivers."""
    times = np.unique([t for _, _, t, _ in records])
    per = []
    for serial in sorted({r[1] for r in records}):
        own = sorted((t, v) for _, s, t, v in records if s == serial)
        per.append(np.interp(times, [t for t, _ in own], [v for _, v in own]))
    return np.column_stack([times, np.mean(per, axis=0)])


@pytest.mark.parametrize("version", ["1.0.0", "2.0.0"])
def test_a_fathom_csv_is_the_receivers_mean_ambient_temperature(tmp_path, version):
    path = tmp_path / "fathom.csv"
    path.write_text(_fathom(version, empty_time=2))
    series = read_temperature_series(path, ORIGIN, absolute=True)
    expected = _expected()
    assert series.shape == expected.shape
    assert np.allclose(series[:, 0], expected[:, 0], atol=1e-5)  # Time (corrected), not the device's clock
    assert np.allclose(series[:, 1], expected[:, 1], atol=1e-9)
    assert series[:, 1].max() < 30.0  # the internal temperature never taken


VUE_EVENTS = [("2021-04-20 17:00:00", "VR2AR-546310", "Temperature", "11.3", "°C"),
              ("2021-04-20 17:00:00", "VR2AR-546310", "Battery", "3.6", "V"),
              ("2021-04-20 17:00:00", "VR2AR-546311", "Average temperature", "12.1", "deg C"),
              ("2021-04-20 17:00:00", "VR2AR-546310", "Daily Pings", "1204", ""),
              ("2021-04-20 18:00:00", "VR2AR-546310", "TEMPERATURE", "11.9", "°C"),
              ("2021-04-20 19:30:00", "VR2AR-546311", "Ambient temperature", "13.0", "C")]


def _vue(events=VUE_EVENTS) -> str:
    return "Date and Time (UTC),Receiver,Description,Data,Units\n" + "".join(",".join(e) + "\n" for e in events)


def test_vue_receiver_events_in_latin1_are_the_receivers_mean_temperature(tmp_path):
    path = tmp_path / "events.csv"
    path.write_bytes(_vue().encode("latin-1"))
    assert b"\xb0C" in path.read_bytes()  # the Latin-1 degree sign, not UTF-8's
    series = read_temperature_series(path, ORIGIN)
    records = [("", serial, pd.Timestamp(t + "Z").timestamp() - ORIGIN, float(v))
               for t, serial, what, v, _ in VUE_EVENTS if "temperature" in what.lower()]
    expected = _expected(records)
    assert np.allclose(series, expected, atol=1e-6)
    assert series[0, 1] == pytest.approx((11.3 + 12.1) / 2) and series[-1, 1] == pytest.approx((11.9 + 13.0) / 2)


@pytest.mark.parametrize("text, found", [
    (_fathom(records=[]), "holds no receiver temperature records (TEMP, TEMP_STATS or DIAG); allowed:"),
    (_vue([e for e in VUE_EVENTS if "temperature" not in e[2].lower()]), "holds no receiver temperature records"),
    (_vue(VUE_EVENTS[:2] + [("2021-04-20 18:00:00", "VR2AR-546310", "Temperature", "52.0", "°F")]),
     "line 4 column Units: '°F' is not allowed; allowed: a temperature in °C"),
    (_vue(VUE_EVENTS[:2] + [("2021-04-20 18:00:00", "VR2AR-546310", "Temperature", "n/a", "°C")]),
     "line 4 column Data: 'n/a' is not allowed; allowed: a finite number in [-2, 40] °C"),
    (_fathom(records=RECORDS[:3] + [("DIAG", "461396", 1500.0, 55.0)]),
     "column Ambient Temperature (deg C): '55.0' is not allowed; allowed: a finite number in [-2, 40] °C"),
    (_fathom(temp=[c if c != "Ambient (deg C)" else "Water (deg C)" for c in TEMP]),
     "TEMP_DESC line needs the columns Device Time (UTC) (or Time), Serial Number and Ambient (deg C)"),
])
def test_bad_receiver_records_are_refused_in_one_line(tmp_path, text, found):
    path = tmp_path / "records.csv"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(ModelError) as error:
        read_temperature_series(path, ORIGIN, absolute=True)
    message = str(error.value)
    assert found in message and "\n" not in message and "temperature file" in message, message


def test_the_line_refused_is_the_files_own(tmp_path):
    """An out-of-range ambient temperature refused at its own line of the file (the csv module's count)."""
    text = _fathom(records=RECORDS[:3] + [("DIAG", "461396", 1500.0, 55.0)])
    line = next(k + 1 for k, row in enumerate(csv.reader(io.StringIO(text))) if row and row[0] == "DIAG")
    path = tmp_path / "records.csv"
    path.write_text(text)
    with pytest.raises(ModelError, match=rf"line {line} column Ambient Temperature"):
        read_temperature_series(path, ORIGIN)


def test_receiver_records_need_the_time_origin(tmp_path):
    path = tmp_path / "fathom.csv"
    path.write_text(_fathom())
    with pytest.raises(ModelError, match="records are in UTC and the times of arrival have no stated origin"):
        read_temperature_series(path)


@pytest.mark.slow
def test_a_study_tracked_with_its_own_fathom_records(tmp_path):
    """``sblsim.track(..., temperature_file=<the Fathom detections>, salinity=35)``: every tag's sound speed is the
    temperature series', TEOS-10's at the records' 9.5 °C in water of practical salinity 35 at the pressure and
    position the summary states (gsw here)."""
    sim = simulate_study(n_receivers=6, n_tags=2, days=0.3, seed=3)
    files = sim.write(tmp_path / "files", "fathom")
    assert ",9.5,10.0" in files["detections"].read_text()  # TEMP records: ambient 9.5, internal 10.0 °C
    result = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"],
                          temperature_file=files["detections"], salinity=35, workers=1)
    check_tag_rows(result.tags, result.tracks)
    assert (result.tags["status"] == "tracked").all() and len(result.tracked) == 2
    for outcome in result.tracked.values():
        speed = outcome.summary["sound_speed"]
        water = speed["water"]
        p = gsw.p_from_z(-water["pressure_depth_m"], water["latitude"])
        sa = gsw.SA_from_SP(35.0, p, water["longitude"], water["latitude"])
        expected = float(gsw.sound_speed(sa, gsw.CT_from_t(sa, 9.5, p), p))
        assert speed["source"] == "temperature series (TEOS-10)"
        assert speed["temperature_range_c"] == [9.5, 9.5]
        assert speed["sound_speed_m_s"] == pytest.approx(expected, abs=0.5)


def test_a_receivers_export_is_read_once_per_file_as_it_is(tmp_path, monkeypatch):
    """Each tag of a study takes the series: the export (the detections file, hundreds of megabytes) read once, and
    again when it changes."""
    from sblsim.orchestrator.readers import water

    path = tmp_path / "fathom.csv"
    path.write_text(_fathom())
    reads = []
    real = water.read_text
    monkeypatch.setattr(water, "read_text", lambda *a, **k: reads.append(k.get("prefix")) or real(*a, **k))
    first = read_temperature_series(path, ORIGIN)
    again = read_temperature_series(path, ORIGIN + 10.0)
    assert reads.count(None) == 1 and np.allclose(again[:, 0], first[:, 0] - 10.0)
    path.write_text(_fathom(records=RECORDS[:2]))
    assert len(read_temperature_series(path, ORIGIN)) == 2 and reads.count(None) == 2
