"""The study report in a real browser (issue 100; slow tier): the ``report.html`` of the boats study, of a simulated
study of 100 tags and of a study whose tags are all refused, each written by ``sblsim track`` (``sblsim.track`` with
``out``) and opened from its file URL in headless Chromium with the network blocked (:mod:`tests.report_browser`):
no console error, no request that failed and none that left the file (every one that was not ``file:`` aborted and
counted), every image decoded (``naturalWidth`` > 0), every in-page link's target present, the tag table's rows
those of ``tags.csv``, a screenshot that is not blank; the page at most 20 MB, and the 100 tags' page loaded in at
most 3 s."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image

import sblsim
from sblsim.orchestrator.telemetry.report.page import MAX_REPORT_BYTES, REPORT_FILE
from sblsim.orchestrator.telemetry.simulate import simulate_study
from tests.orchestrator.test_study_report_page import refused_study
from tests.report_browser import CHROMIUM, inspect_page, open_report

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
BOATS = ROOT / "data" / "boats-norway"
#: The 100 tags' page's longest load [s].
MAX_LOAD_S = 3.0


@pytest.fixture(scope="module")
def studies(tmp_path_factory) -> dict[str, Path]:
    """The three studies' folders, each written by sblsim.track."""
    if not CHROMIUM.exists():
        pytest.fail(f"no Chromium at {CHROMIUM}: install Debian's package (apt-get install -y chromium; .ci/run "
                    "does as root)")
    tmp = tmp_path_factory.mktemp("reports")
    sblsim.track(BOATS / "detections.csv", receivers=BOATS / "deployments.csv", tags=BOATS / "tags.csv",
                 out=tmp / "boats")
    sim = simulate_study(n_receivers=16, n_tags=100, days=0.25, redeployed=2, seed=1)
    files = sim.write(tmp / "simulated", "vue")
    sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"], out=tmp / "hundred")
    refused, _ = refused_study(tmp / "refused")
    return {"boats": tmp / "boats", "hundred": tmp / "hundred", "refused": refused}


def _not_blank(png: bytes) -> bool:
    """A screenshot with text and figures: many colours, and pixels far from the page's background."""
    picture = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), float)
    colours = len(np.unique(picture.reshape(-1, 3), axis=0))
    return colours > 50 and float((np.abs(picture - picture[0, 0]).sum(axis=2) > 60).mean()) > 0.02


@pytest.mark.parametrize("name", ["boats", "hundred", "refused"])
def test_the_report_opens_offline_whole(studies, name):
    folder = studies[name]
    report = folder / REPORT_FILE
    assert report.stat().st_size <= MAX_REPORT_BYTES
    tags = pd.read_csv(folder / "tags.csv", dtype=str, keep_default_na=False)
    with open_report(report) as opened:
        shown = inspect_page(opened)
        png = opened.page.screenshot()
    print(f"{name}: {report.stat().st_size / 2**20:.2f} MiB, {len(shown['images'])} images, loaded in "
          f"{opened.load_s:.2f} s")
    assert opened.errors == [] and opened.failed == [] and opened.blocked == []
    assert shown["images"] and all(i["complete"] and i["width"] > 0 for i in shown["images"])
    assert all(s.startswith("data:image/png;base64,") for s in shown["sources"])
    assert shown["missing"] == [] and len(shown["links"]) >= len(tags)
    assert shown["scripts"] == 0
    assert shown["tag_rows"] == len(tags)
    assert shown["tag_links"] == [t or tr for t, tr in zip(tags["tag"], tags["transmitter"])]
    assert _not_blank(png)
    if name == "hundred":
        assert len(tags) == 100 and opened.load_s <= MAX_LOAD_S
    if name == "refused":
        assert set(tags["status"]) == {"refused"}


def test_a_blank_screenshot_is_told_apart():
    """The screenshot check can fail: a page of one colour is blank."""
    out = io.BytesIO()
    Image.new("RGB", (320, 200), (255, 255, 255)).save(out, format="PNG")
    assert not _not_blank(out.getvalue())
