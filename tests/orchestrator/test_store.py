"""The detections store (:mod:`sblsim.orchestrator.store`): a file read into it a piece at a time gives what the
whole-file reader (:func:`read_detections`) gives, in every format, read back whole or a tag at a time; its
refusals are the reader's, and a refused, full or foreign output leaves nothing behind."""

from __future__ import annotations

import errno
import json

import numpy as np
import pandas as pd
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.detections import read_detections
from sblsim.orchestrator.store import ingest as ingest_module
from sblsim.orchestrator.store.ingest import ingest
from sblsim.orchestrator.store.query import Store
from sblsim.orchestrator.telemetry.simulate import fathom_text, simulate_study, vue_text


@pytest.fixture(scope="module")
def detections() -> pd.DataFrame:
    """A simulated study's detections (``serial``, ``model``, ``transmitter``, ``time``), one receiver's clock set
    back an hour half way through its log (a reset at a download), a few hundred rows a tag."""
    d = simulate_study(n_receivers=5, n_tags=3, days=0.25, seed=3).detections.reset_index(drop=True)
    first = d["serial"].iloc[0]
    mine = np.flatnonzero(d["serial"].to_numpy() == first)
    later = mine[len(mine) // 2:]
    d.loc[later, "time"] = d.loc[later, "time"] - 3600.0
    return d


def _iso(seconds) -> pd.Series:
    return pd.to_datetime(np.asarray(seconds) * 1e6, unit="us").strftime("%Y-%m-%d %H:%M:%S.%f")


def _text(d: pd.DataFrame, format: str) -> str:
    """``d`` written as ``format``'s file would be (the network extracts with a duplicated row and a receiver cell
    with a note)."""
    space = d["transmitter"].str.rpartition("-")[0]
    ident = d["transmitter"].str.rpartition("-")[2]
    if format == "vue":
        return vue_text(d)
    if format == "fathom":
        return fathom_text(d)
    if format == "yaps":
        t = d["time"].to_numpy()
        table = pd.DataFrame({"epo": np.floor(t).astype(np.int64), "frac": np.round(t - np.floor(t), 6),
                              "tag": ident, "serial": d["serial"]})
    elif format == "actel":
        table = pd.DataFrame({"Timestamp": _iso(d["time"]), "Receiver": d["serial"], "CodeSpace": space,
                              "Signal": ident, "Sensor.Value": "NA", "Sensor.Unit": "NA"})
    elif format == "thelma":  # the date's second is the Unix time's, to the millisecond
        ms = np.floor(d["time"].to_numpy() * 1000) / 1000
        table = pd.DataFrame({"Date and Time (UTC)": _iso(ms).str.slice(0, 19),
                              "Unix Timestamp (UTC)": [f"{t:.3f}" for t in ms], "ID": ident, "Data": "-",
                              "Protocol": "R64K-69kHz", "SNR": 30, "Receiver": d["serial"]})
    else:  # a network's extract: sorted by animal and time, one row twice, a receiver noted
        receiver = d["serial"].astype(str).copy()
        receiver.iloc[5] = receiver.iloc[5] + "(lost/found)"
        if format == "glatos":
            table = pd.DataFrame({"animal_id": ident, "detection_timestamp_utc": _iso(d["time"]),
                                  "transmitter_codespace": space, "transmitter_id": ident, "sensor_value": "",
                                  "sensor_unit": "", "receiver_sn": receiver, "station": "S1"})
        else:
            table = pd.DataFrame({"catalogNumber": ident, "receiver": receiver, "tagName": d["transmitter"],
                                  "dateCollectedUTC": _iso(d["time"]), "station": "HFX1"})
        table = pd.concat([table, table.iloc[[7]]]).sort_values([table.columns[0], table.columns[1]], kind="stable")
    return table.to_csv(index=False)


FORMATS = ["yaps", "vue", "fathom", "glatos", "otn", "actel", "thelma"]


@pytest.mark.parametrize("format", FORMATS)
def test_the_store_holds_what_the_whole_file_reader_reads(detections, tmp_path, format):
    path = tmp_path / "detections.csv"
    path.write_text(_text(detections, format))
    want = read_detections(path, None)
    info = ingest(path, tmp_path / "store", piece_bytes=8192)
    assert info["files"] > 5  # many pieces: the carried clock parts, headers and _DESC lines are exercised
    store = Store(tmp_path / "store")
    got = store.detections()
    pd.testing.assert_frame_equal(got.frame, want.frame)
    assert got.format == want.format == format and got.row_order == want.row_order
    assert got.clock_resets == want.clock_resets and got.ignored_columns == want.ignored_columns
    assert got.duplicates == want.duplicates and got.notes == want.notes
    if format not in ("glatos", "otn"):
        assert len(want.clock_resets) == 1  # the hour set back is found across pieces
    else:
        assert want.duplicates == 1 and want.notes
    assert info["rows"] == len(want.frame) + want.duplicates == sum(store.info["tags"].values())
    tags = want.frame["tag"].value_counts()
    assert sorted(store.tags) == sorted(tags.index)
    one = tags.index[0]  # a tag read alone: the whole file's rows of that tag, in their order
    pd.testing.assert_frame_equal(store.frame(tags=[one]), want.frame[want.frame["tag"] == one].reset_index(drop=True))
    narrow = store.detections(columns=["serial"])  # a few columns read from the files: the whole file's, narrowed
    keep = [c for c in want.frame.columns if c in ("serial", "receiver", "tag", "time", "line", "clock_part")]
    assert len(keep) < len(want.frame.columns)
    pd.testing.assert_frame_equal(narrow.frame, want.frame[keep])
    assert narrow.duplicates == want.duplicates and narrow.notes == want.notes


def test_a_time_window_and_receivers_read_alone(detections, tmp_path):
    path = tmp_path / "d.csv"
    path.write_text(_text(detections, "vue"))
    want = read_detections(path, None).frame
    ingest(path, tmp_path / "s", piece_bytes=8192)
    start, end = np.quantile(want["time"], [0.3, 0.6])
    receiver = want["receiver"].iloc[0]
    got = Store(tmp_path / "s").frame(receivers=[receiver], start=start, end=end)
    mask = (want["receiver"] == receiver) & (want["time"] >= start) & (want["time"] < end)
    pd.testing.assert_frame_equal(got, want[mask].reset_index(drop=True))


def test_a_latin_1_file_is_read_as_the_reader_reads_it(detections, tmp_path):
    text = _text(detections, "vue").replace("Station Name", "Station Name,Note", 1)
    rows = text.splitlines()
    rows = [rows[0]] + [r + (",19 °C" if k == len(rows) - 3 else ",") for k, r in enumerate(rows[1:], 1)]
    path = tmp_path / "latin.csv"
    path.write_bytes(("\n".join(rows) + "\n").encode("latin-1"))
    want = read_detections(path, None)
    info = ingest(path, tmp_path / "s", piece_bytes=16384)
    assert info["encoding"] == "latin-1"
    pd.testing.assert_frame_equal(Store(tmp_path / "s").detections().frame, want.frame)


def test_a_bad_cell_late_in_the_file_is_the_readers_line_and_nothing_is_written(detections, tmp_path):
    lines = _text(detections, "vue").splitlines()
    k = len(lines) - 4
    lines[k] = lines[k].replace(",A69-", ",A69+", 1)
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ModelError) as whole:
        read_detections(path, None)
    with pytest.raises(ModelError) as pieces:
        ingest(path, tmp_path / "out" / "s", piece_bytes=16384)
    assert str(pieces.value) == str(whole.value) and f"line {k + 1}" in str(whole.value)
    assert not (tmp_path / "out").exists()


def test_a_receiver_sorted_by_tag_is_refused_as_the_reader_refuses_it(detections, tmp_path):
    d = detections[detections["serial"] == detections["serial"].iloc[-1]].sort_values("transmitter", kind="stable")
    path = tmp_path / "sorted.csv"
    path.write_text(vue_text(d))
    with pytest.raises(ModelError) as whole:
        read_detections(path, None)
    with pytest.raises(ModelError) as pieces:
        ingest(path, tmp_path / "s", piece_bytes=16384)
    assert str(pieces.value) == str(whole.value)


def test_no_room_on_the_disk_is_said_before_the_work(detections, tmp_path, monkeypatch):
    path = tmp_path / "d.csv"
    path.write_text(_text(detections, "vue"))
    size = path.stat().st_size
    monkeypatch.setattr(ingest_module.shutil, "disk_usage", lambda p: type("U", (), {"free": size - 1})())
    with pytest.raises(ModelError, match=r"^--out: .* needs up to .* MiB \(the file's size\) and the disk holds"):
        ingest(path, tmp_path / "s")
    assert not (tmp_path / "s").exists()


def test_a_disk_that_fills_leaves_nothing(detections, tmp_path, monkeypatch):
    import pyarrow.parquet as pq

    path = tmp_path / "d.csv"
    path.write_text(_text(detections, "vue"))
    written = []

    def full(table, where, **options):
        if written:
            raise OSError(errno.ENOSPC, "No space left on device")
        written.append(where)
        pq_write(table, where, **options)

    pq_write = pq.write_table
    monkeypatch.setattr(pq, "write_table", full)
    with pytest.raises(ModelError, match=r"^--out: .*: the store could not be written \(No space left on device\)"):
        ingest(path, tmp_path / "s", piece_bytes=16384)
    assert written and not (tmp_path / "s").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["d.csv"]


def test_a_folder_that_is_no_store_is_refused_and_a_foreign_file_kept(detections, tmp_path):
    path = tmp_path / "d.csv"
    path.write_text(_text(detections, "vue"))
    (tmp_path / "s").mkdir()
    (tmp_path / "s" / "store.json").write_text("{}")
    with pytest.raises(ModelError, match="not a store's description"):
        Store(tmp_path / "s")
    with pytest.raises(ModelError):
        ingest(path, tmp_path / "s", piece_bytes=16384)  # a store.json sblsim did not write is never replaced
    assert (tmp_path / "s" / "store.json").read_text() == "{}"
    info = ingest(path, tmp_path / "t", piece_bytes=16384)
    described = json.loads((tmp_path / "t" / "store.json").read_text())
    assert described["rows"] == info["rows"] and described["source"] == "d.csv"
    part = next((tmp_path / "t" / "detections").iterdir())
    part.unlink()
    with pytest.raises(ModelError, match="holds .* files where store.json says"):
        Store(tmp_path / "t")


def test_a_store_folder_is_read_as_its_file_by_track_sync_and_toa(detections, tmp_path):
    from sblsim.orchestrator.readers.study_files import read_many, study_files
    from sblsim.orchestrator.store.read import read_any

    path = tmp_path / "d.csv"
    path.write_text(_text(detections, "fathom"))
    ingest(path, tmp_path / "s")
    want = read_detections(path, None)
    pd.testing.assert_frame_equal(read_any(tmp_path / "s").frame, want.frame)
    files = study_files(tmp_path / "s", receivers=path)
    assert list(files.detections) == [tmp_path / "s"]  # the store, not its folder's files
    pd.testing.assert_frame_equal(read_many(files.detections).frame, want.frame)
    with pytest.raises(ModelError, match=r"^format: 'vue', but the store .* holds 'fathom' detections"):
        read_any(tmp_path / "s", "vue")


def test_the_command_says_what_it_stored_and_refuses_in_one_line(detections, tmp_path, capsys):
    from sblsim.orchestrator.cli import main

    path = tmp_path / "d.csv"
    path.write_text(_text(detections, "vue"))
    assert main(["store", str(path), "--out", str(tmp_path / "s")]) == 0
    said = capsys.readouterr().out.splitlines()
    frame = read_detections(path, None).frame
    assert said[0].startswith(f"store: {len(frame):,} detections of {frame['tag'].nunique()} tags at "
                              f"{frame['receiver'].nunique()} receivers (vue, ")
    assert any(line.startswith("note: receiver ") and "part 2" in line for line in said)  # the clock set back
    before = sorted(p.name for p in (tmp_path / "s").rglob("*"))
    assert main(["store", str(path), "--out", str(tmp_path / "s")]) == 2  # an earlier store: --force
    assert "holds an earlier store" in capsys.readouterr().err
    path.write_text(_text(detections, "vue").replace("VR2AR-", "VR2AR-?", 1))
    assert main(["store", str(path), "--out", str(tmp_path / "s"), "--force"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("sblsim: error: detections: ") and "line 2 column Receiver" in err[0]
    assert sorted(p.name for p in (tmp_path / "s").rglob("*")) == before  # the earlier store kept whole


def test_a_store_from_a_stranger_is_checked_before_its_detections_are_used(detections, tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = tmp_path / "d.csv"
    path.write_text(_text(detections, "vue"))
    ingest(path, tmp_path / "s")
    described = json.loads((tmp_path / "s" / "store.json").read_text())
    for key, value in (("rows", "many"), ("clock_resets", [{"receiver": 1}]), ("format", "xls"), ("tags", [])):
        (tmp_path / "s" / "store.json").write_text(json.dumps(described | {key: value}))
        with pytest.raises(ModelError, match=r"^store: .*store.json's"):
            Store(tmp_path / "s")
    (tmp_path / "s" / "store.json").write_text(json.dumps(described))
    part = next((tmp_path / "s" / "detections").iterdir())
    table = pq.read_table(part)
    pq.write_table(table.set_column(table.column_names.index("time"), "time",
                                    pa.array([str(t) for t in table.column("time").to_pylist()])), part)
    with pytest.raises(ModelError, match=r"its detections' columns time \(string\); allowed: .*time \(double\)"):
        Store(tmp_path / "s").frame()
    times = table.column("time").to_numpy().copy()
    times[3] = -1.0
    pq.write_table(table.set_column(table.column_names.index("time"), "time", pa.array(times)), part)
    with pytest.raises(ModelError, match=r"line \d+'s time -1.0 s; allowed: a time from 1970"):
        Store(tmp_path / "s").frame()


def test_a_file_too_large_to_read_whole_says_so_and_is_read_from_its_store(detections, tmp_path, monkeypatch):
    from sblsim.orchestrator.readers import detections as reader
    from sblsim.orchestrator.store.read import read_any

    path = tmp_path / "d.csv"
    path.write_text(_text(detections, "vue"))
    want = read_detections(path, None).frame
    monkeypatch.setattr(reader, "MAX_DETECTION_BYTES", 2**14)  # the file is beyond the whole-file reader
    said = r"MiB; allowed at most 0 MiB and 3,000,000 rows read whole \(a larger file: sblsim store FILE --out DIR, "
    with pytest.raises(ModelError, match=said + r"then DIR in the file's place\)$"):
        read_detections(path, None)
    ingest(path, tmp_path / "s", piece_bytes=16384)
    pd.testing.assert_frame_equal(read_any(tmp_path / "s").frame, want)


@pytest.mark.slow
def test_sync_of_a_store_reads_its_sync_tags_alone_and_fits_the_clocks_of_its_file(tmp_path, monkeypatch):
    """``sblsim sync`` on a store asks the store for the deployments' sync tags' rows alone (the animals' never
    read) and fits the same clocks as on the file it was stored from (offsets within a nanosecond: the frame is
    chosen over the same deployments)."""
    import sblsim
    from sblsim.orchestrator.store import query

    sim = simulate_study(n_receivers=5, n_tags=3, days=0.25, seed=3)
    files = sim.write(tmp_path / "study", "vue")
    ingest(files["detections"], tmp_path / "s")
    asked = []
    real = query.Store.detections

    def spy(self, tags=None, *args, **kwargs):
        asked.append(tags)
        return real(self, tags, *args, **kwargs)

    monkeypatch.setattr(query.Store, "detections", spy)
    from_store = sblsim.sync(tmp_path / "s", receivers=files["deployments"], sound_speed=1480.0)
    from_file = sblsim.sync(files["detections"], receivers=files["deployments"], sound_speed=1480.0)
    sync_tags = set(pd.read_csv(files["deployments"])["transmitter"])
    assert asked == [sorted(sync_tags)]
    held, whole = from_store.summary["detections"], from_file.summary["detections"]
    assert held["sync_arrivals"] == whole["sync_arrivals"] == held["rows"] < whole["rows"]
    a, b = from_store.offsets, from_file.offsets
    assert list(a["receiver"]) == list(b["receiver"]) and list(a["bin"]) == list(b["bin"])
    assert np.allclose(a["offset_start_s"], b["offset_start_s"], rtol=0, atol=1e-9)


@pytest.mark.slow
def test_toa_of_a_store_reads_its_tag_alone_and_builds_its_files_matrix(tmp_path, monkeypatch):
    """``sblsim toa`` on a store asks it for the tag's rows alone and builds the matrix it builds from the file (the
    same pings, receivers and times); a tag the store never holds refused in one line naming the store's tags."""
    import sblsim
    from sblsim.orchestrator.store import query

    sim = simulate_study(n_receivers=5, n_tags=3, days=0.25, seed=3)
    files = sim.write(tmp_path / "study", "vue")
    ingest(files["detections"], tmp_path / "s")
    sblsim.sync(files["detections"], receivers=files["deployments"], sound_speed=1480.0, out=tmp_path / "sync")
    tag = sim.sheet["transmitter"].iloc[0]
    from_file = sblsim.toa(files["detections"], receivers=files["deployments"], sync=tmp_path / "sync", tag=tag)
    asked = []
    real = query.Store.detections
    monkeypatch.setattr(query.Store, "detections", lambda self, tags=None, *a, **k: asked.append(tags)
                        or real(self, tags, *a, **k))
    from_store = sblsim.toa(tmp_path / "s", receivers=files["deployments"], sync=tmp_path / "sync", tag=tag)
    assert asked == [[tag]]
    assert from_store.receivers == from_file.receivers
    np.testing.assert_array_equal(from_store.toa, from_file.toa)
    with pytest.raises(ModelError, match=r"^tag: A69-9999-1 is never detected in the store .*; allowed: one of A69"):
        sblsim.toa(tmp_path / "s", receivers=files["deployments"], sync=tmp_path / "sync", tag="A69-9999-1")


@pytest.mark.slow
def test_a_store_study_holds_the_sync_residuals_on_disk_while_its_tags_are_built_and_tracked(tmp_path, monkeypatch):
    """A study of a store (``sblsim track STORE --out``) keeps the synchronisation's row per sync-tag arrival on disk
    from the synchronisation's end while each tag's matrix is made and the tags are tracked (a folder of its own in
    the output, the table gone from memory), then has it back whole: the study's ``sync/residuals.csv`` is the same
    as a study of the file it was stored from."""
    import sblsim
    from sblsim.orchestrator.telemetry import study as study_module

    sim = simulate_study(n_receivers=5, n_tags=3, days=0.25, seed=3)
    files = sim.write(tmp_path / "study", "vue")
    ingest(files["detections"], tmp_path / "s")
    seen = []
    for name in ("build_toa", "run_tracks"):
        real = getattr(study_module, name)

        def spy(*args, _real=real, _name=name, **kwargs):
            seen.append((_name, [p.name for p in tmp_path.rglob(".held-*")]))  # (in the run's own folder)
            return _real(*args, **kwargs)

        monkeypatch.setattr(study_module, name, spy)
    sblsim.track(tmp_path / "s", receivers=files["deployments"], tags=files["tags"], sound_speed=1480.0,
                 out=tmp_path / "out")
    assert {name for name, _ in seen} == {"build_toa", "run_tracks"}
    assert all(len(held) == 1 for _, held in seen)  # on disk at each
    assert not list(tmp_path.rglob(".held-*"))  # and back after, its folder gone
    monkeypatch.undo()
    sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"], sound_speed=1480.0,
                 out=tmp_path / "file")
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "out" / "sync" / "residuals.csv"),
                                  pd.read_csv(tmp_path / "file" / "sync" / "residuals.csv"))
