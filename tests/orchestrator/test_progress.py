"""One progress reporter for every long command: :class:`sblsim.orchestrator.io.progress.Progress`.

A campaign and a compare report through the same class, and their callbacks receive the same fields (units
done, units in all); the log lines' arithmetic (rate, time left, the campaign's resumed start and its forced
first and last lines) is checked against numbers worked out by hand on a controlled clock.
"""

from __future__ import annotations

import re

import pytest

import sblsim
from sblsim.orchestrator.campaign import run_campaign
from sblsim.orchestrator.campaign.study import load_study
from sblsim.orchestrator.io import progress as progress_module
from sblsim.orchestrator.io.progress import Progress

DURATION, T, REPLICATES = 10.0, 0.1, 2


def tiny_study(tmp_path):
    import tomli_w

    study = {"study": {"name": "tiny", "scenarios": ["semicircle"], "replicates": REPLICATES, "seed": 3,
                       "set": [f"simulation.duration={DURATION}"]},
             "factors": [{"name": "baseline", "key": "platform.baseline", "low": 0.5, "high": 2.0},
                         {"name": "range", "key": "acoustics.sigma_range", "low": 0.05, "high": 0.2}]}
    path = tmp_path / "tiny.toml"
    path.write_text(tomli_w.dumps(study))
    return path


class Clock:
    """A ``time.perf_counter`` the test sets [s]."""

    def __init__(self, now: float) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


def test_campaign_and_compare_report_through_the_same_class(tmp_path, monkeypatch):
    reporters = []
    update = Progress.update

    def spy(self, units=1):
        reporters.append((type(self), self.desc, self.unit))
        return update(self, units)

    monkeypatch.setattr(Progress, "update", spy)
    fields = {"campaign": [], "compare": []}
    result = sblsim.campaign(tiny_study(tmp_path), tmp_path / "c", workers=1,
                             progress=lambda *args: fields["campaign"].append(args))
    sblsim.compare("semicircle", receivers=["ekf", "ekf-seq"], replicates=REPLICATES,
                   set={"simulation.duration": DURATION}, progress=lambda *args: fields["compare"].append(args))
    assert {(desc, unit) for cls, desc, unit in reporters if cls is Progress} >= {("campaign", "run"),
                                                                                  ("compare", "step")}
    assert all(cls is Progress for cls, _, _ in reporters)
    # the same fields: (units done, units in all), done rising to the total
    cells = 2 ** 2
    expected = {"campaign": cells * REPLICATES, "compare": 2 * round(DURATION / T) * REPLICATES}
    assert result.total == expected["campaign"]
    for name, calls in fields.items():
        assert all(len(call) == 2 for call in calls), (name, calls)
        done = [d for d, _ in calls]
        assert {t for _, t in calls} == {expected[name]}, (name, calls)
        assert done == sorted(done) and done[-1] == expected[name], (name, done)
    assert fields["campaign"][0] == (0, expected["campaign"])  # a campaign reports its start at once


def test_the_campaign_log_line_rate_time_left_resumed_start_and_forced_ends(monkeypatch, capsys):
    clock = Clock(100.0)
    monkeypatch.setattr(progress_module.time, "perf_counter", clock)
    reporter = Progress(8, "campaign", "run", "log", initial=2, ends=True, rate=True)  # 2 runs done before
    clock.now = 104.0
    reporter.update(2)  # 4 s: no line (every 10 s)
    clock.now = 112.0
    reporter.update(2)  # 6 of 8; 4 runs in 12 s: 0.33 runs/s, 2 runs left: 6 s
    clock.now = 113.0
    reporter.update(2)  # done: the last line at once; 6 runs in 13 s
    reporter.close()
    assert capsys.readouterr().err.splitlines() == [
        "campaign: 2/8 runs (25 %), 0.0 runs/s",
        "campaign: 6/8 runs (75 %), 0.3 runs/s, about 6 s left",
        "campaign: 8/8 runs (100 %), 0.5 runs/s",
    ]


def test_the_plain_log_line_has_no_forced_ends_and_no_rate_and_a_callback_starts_where_told(monkeypatch, capsys):
    clock = Clock(0.0)
    monkeypatch.setattr(progress_module.time, "perf_counter", clock)
    calls = []
    with Progress(200, "compare", "step", "log") as reporter:
        for now, units in ((5.0, 50), (10.0, 50), (12.0, 100)):
            clock.now = now
            reporter.update(units)
    assert capsys.readouterr().err.splitlines() == ["compare: 100/200 steps (50 %), about 10 s left"]
    with Progress(8, "campaign", "run", lambda *args: calls.append(args), initial=3, ends=True) as reporter:
        reporter.update(5)
    assert calls == [(3, 8), (8, 8)]  # with ends, the callback's first call at once, from the resumed start


def test_a_resumed_campaign_reports_from_where_it_stands(tmp_path, capsys):
    study = load_study(str(tiny_study(tmp_path)))
    out = tmp_path / "c"
    run_campaign(study, out, workers=1, batch=REPLICATES, progress=False)  # one chunk per cell
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("campaign: ")]
    total = study.runs
    assert lines[0] == f"campaign: 0/{total} runs (0 %), 0.0 runs/s"
    assert re.fullmatch(rf"campaign: {total}/{total} runs \(100 %\), \d+\.\d runs/s", lines[-1]), lines
    chunks = sorted((out / "chunks").glob("*.parquet"))
    assert len(chunks) == total // REPLICATES
    chunks[0].unlink()
    run_campaign(study, out, workers=1, resume=True, progress=False)
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("campaign: ")]
    done = total - REPLICATES
    assert lines[0] == f"campaign: {done}/{total} runs ({100 * done / total:.0f} %), 0.0 runs/s"
    assert re.fullmatch(rf"campaign: {total}/{total} runs \(100 %\), \d+\.\d runs/s", lines[-1]), lines


def test_a_bad_progress_spec_is_refused():
    with pytest.raises(ValueError, match="progress"):
        Progress(10, "run", spec="loud")
