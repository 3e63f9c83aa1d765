"""The HTML report: one self-contained file whose sections follow the data."""

from __future__ import annotations

import base64
import html
import math
import re
import shutil
import subprocess
import time
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from stickslip.diagnostics.report_html import write_report
from stickslip.estimators.table import ResultTable
from stickslip.traces.trace import Trace

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
VOID = {
    "area",
    "base",
    "br",
    "col",
    "embed",
    "hr",
    "img",
    "input",
    "link",
    "meta",
    "source",
    "track",
    "wbr",
}
EVIL = "<script>alert('x')</script>&"


class Page(HTMLParser):
    """Collects the structure of a page: tag balance, images, links, sections, rows."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.imgs: list[str] = []
        self.urls: list[str] = []
        self.sections: list[str] = []
        self.tags: set[str] = set()
        self.ids: set[str] = set()
        self.rows: dict[str, int] = {}
        self._table: list[str | None] = []
        self._in_tbody = False
        self.text: list[str] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.add(tag)
        if a.get("id"):
            assert a["id"] not in self.ids, f"duplicate id {a['id']}"
            self.ids.add(a["id"])
        for k in ("src", "href", "action", "data", "poster"):
            if a.get(k):
                self.urls.append(a[k])
        if tag == "img":
            self.imgs.append(a.get("src") or "")
        if tag == "section":
            self.sections.append(a.get("id") or "")
        if tag == "table":
            self._table.append(a.get("id"))
        if tag == "tbody":
            self._in_tbody = True
        if tag == "tr" and self._in_tbody and self._table and self._table[-1]:
            self.rows[self._table[-1]] = self.rows.get(self._table[-1], 0) + 1
        if tag not in VOID:
            self.stack.append(tag)

    def handle_startendtag(self, tag, attrs):
        self.handle_starttag(tag, attrs)
        if tag not in VOID:
            self.stack.pop()

    def handle_endtag(self, tag):
        if tag in VOID:
            return
        if not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes <{self.stack[-1] if self.stack else None}>")
            return
        self.stack.pop()
        if tag == "table":
            self._table.pop()
        if tag == "tbody":
            self._in_tbody = False

    def handle_data(self, data):
        self.text.append(data)


def parse(path: Path) -> tuple[str, Page]:
    doc = path.read_text(encoding="utf-8")
    page = Page()
    page.feed(doc)
    page.close()
    return doc, page


def sawtooth(n_px: int, level_nN: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A stick-slip-like line: rising ramps and sudden drops, with noise."""
    rng = np.random.default_rng(seed)
    x = np.arange(n_px) * (11.0 / n_px)
    f = level_nN * (2 * ((x / 0.246) % 1.0) - 0.2) + rng.normal(0, 0.05, n_px)
    return x, f


def fake_run(
    *,
    intervals: bool = True,
    classical: bool = True,
    loads: bool = True,
    domain: bool = False,
    map_lines: int = 8,
    singles: bool = True,
    evil: bool = False,
):
    """A table, its traces, run info and overlays: one 2-direction map, two single traces
    and an unreadable input."""
    traces: list[Trace] = []
    rows: list[dict] = []
    rng = np.random.default_rng(0)
    width = max(3, len(str(map_lines - 1)))
    for line in range(map_lines):
        for direction in ("trace", "retrace"):
            x, f = sawtooth(128, 1.0 + 0.05 * line, seed=line * 2 + (direction == "retrace"))
            meta = {"line": line, "direction": direction, "channel": "Lateral", "unit": "nN"}
            if loads:
                meta.update(load=5.0 if line < map_lines // 2 else 10.0, load_unit="nN")
            traces.append(
                Trace(x, f, f"scan:Lateral:{direction}:L{line:0{width}d}", "/data/scan.spm", meta)
            )
    if singles:
        for i in range(2):
            x, f = sawtooth(200, 0.8, seed=100 + i)
            traces.append(Trace(x, f, f"single{i}", f"/data/single{i}.csv", {}))
    for i, t in enumerate(traces):
        U0, K = 1.0 + 0.1 * rng.standard_normal(), 15.0 + rng.standard_normal()
        row = {
            "trace": t.name,
            "estimator": "line-cnn",
            "quality": "ok",
            "F_mean_nN": float(t.force_nN.mean()),
            "U0_eV": U0,
            "K_N_m": K,
            "eta": 52.26 * U0 / K,
            "U0_eV_std": 0.1,
            "K_N_m_std": 1.0,
            "lattice_nm": 0.246,
            "lattice_source": "model",
            "velocity_nm_per_s": 60.0,
            "velocity_source": "flag",
            "temperature_K": 296.0,
            "temperature_source": "model",
            "file": t.source,
            "gof": 1.0,
            "ppc_flag": 0,
        }
        for k in ("channel", "direction", "line", "load", "load_unit"):
            if k in t.meta:
                row[k] = t.meta[k]
        if intervals:
            for key, v, s in (
                ("F_mean_nN", row["F_mean_nN"], 0.05),
                ("U0_eV", U0, 0.1),
                ("K_N_m", K, 1.0),
                ("eta", row["eta"], 0.3),
            ):
                row.update(
                    {
                        f"{key}_lo68": v - s,
                        f"{key}_hi68": v + s,
                        f"{key}_lo95": v - 2 * s,
                        f"{key}_hi95": v + 2 * s,
                    }
                )
        if classical:
            row.update(classical_U0_eV=U0 * 0.9, classical_K_N_m=K * 1.1, classical_quality="ok")
        if domain:
            row.update(
                in_domain=i % 5 != 0,
                domain_score=0.3 * (i % 5),
                domain_reason="" if i % 5 else "force range far beyond training",
            )
        rows.append(row)
    # a PPC-flagged line, and a line refused by the estimator
    ppc, refused = min(3, len(rows) - 2), min(5, len(rows) - 1)
    rows[ppc].update(ppc_flag=1, gof=5.2)
    for k in ("F_mean_nN", "U0_eV", "K_N_m", "eta"):
        rows[refused][k] = math.nan
    rows[refused]["quality"] = "too short: 100 mapped pixels, at least 256 needed"
    if evil:
        traces[0].name = rows[0]["trace"] = "L0" + EVIL
        rows[0]["ppc_flag"] = 1
    # an unreadable input: a row without a trace, in the middle of the table
    rows.insert(
        4,
        {
            "trace": "broken",
            "estimator": "line-cnn",
            "file": "/data/broken.csv",
            "quality": "not a trace file: no x_nm column",
        },
    )
    table = ResultTable(
        rows=rows, estimator="line-cnn", intervals=intervals, notes=["model trained at T = 296 K"]
    )
    overlays = {t.name: t.force_nN + 0.1 for t in traces[:4]}
    info = {
        "files": ["/data/scan.spm", "/data/single0.csv", "/data/single1.csv", "/data/broken.csv"],
        "model": "line-cnn",
        "model_version": "2025.1",
        "command": ["stickslip", "infer", "--report", "r.html", "/data/scan.spm"],
        "unreadable": [("/data/broken.csv", "not a trace file: no x_nm column")],
        "conditions": {"velocity_nm_per_s": (60.0, "flag")},
    }
    return table, traces, info, overlays


def check_self_contained(doc: str, page: Page, images: bool = True) -> None:
    assert not page.errors, page.errors[:5]
    assert not page.stack, f"unclosed tags: {page.stack}"
    assert {"html", "head", "body", "style", "table"} <= page.tags
    assert not page.tags & {"script", "link", "iframe", "object", "embed"}
    assert "http://" not in doc and "https://" not in doc
    assert "url(" not in doc and "@import" not in doc
    for url in page.urls:
        assert url.startswith(("data:image/png;base64,", "#")), url[:60]
        if url.startswith("#"):  # in-page links lead somewhere
            assert url[1:] in page.ids, url
    assert bool(page.imgs) == images
    for src in page.imgs:
        assert src.startswith("data:image/png;base64,")
        data = base64.b64decode(src.split(",", 1)[1], validate=True)
        assert data.startswith(PNG_MAGIC) and len(data) > 1000


def test_full_report_is_self_contained_and_has_every_section(tmp_path):
    table, traces, info, overlays = fake_run()
    out = write_report(tmp_path / "report.html", table, traces, info, overlays)
    assert out == tmp_path / "report.html"
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]  # no temporary left
    doc, page = parse(out)
    check_self_contained(doc, page)
    assert page.sections == ["run", "results", "maps", "load", "classical", "gallery"]
    assert page.rows["results-table"] == len(table) == 16 + 2 + 1
    assert page.rows["full-table"] == len(table)
    text = " ".join(page.text)
    # counts: 19 rows, 1 unreadable, 1 refused + 1 PPC flagged, 16 ok
    assert "19 rows" in text and "16 ok" in text and "1 unreadable" in text
    assert "2 flagged (1 without estimate, 1 PPC)" in text
    assert "out of domain" not in text and "in_domain" not in doc  # no such column
    assert "/data/broken.csv" in text and "no x_nm column" in text
    assert "line-cnn" in text and "2025.1" in text and "stickslip infer --report" in text
    # conditions with their sources, from the rows
    assert "lattice spacing a (nm)" in text and "flag" in text and "model" in text
    # the map: one image for one file/channel; gallery: both flagged rows, with overlay
    assert "scan.spm \u2014 Lateral" in text
    assert "8 scan lines" in text and "8 trace, 8 retrace" in text
    assert 'id="g3"' in doc and 'id="g6"' in doc  # the PPC row and the refused one
    assert "2 flagged traces, 2 shown" in text and "PT model at the estimate" in text
    assert "95 % interval" in text
    # 1 map + 1 load + 1 classical + 2 gallery panels
    assert len(page.imgs) == 5


def test_sections_follow_the_data(tmp_path):
    table, traces, info, _ = fake_run(intervals=False, classical=False, loads=False, map_lines=0)
    doc, page = parse(write_report(tmp_path / "r.html", table, traces, info))
    check_self_contained(doc, page)
    assert page.sections == ["run", "results", "gallery"]
    assert page.rows["results-table"] == len(table)
    text = " ".join(page.text)
    assert "95 %" not in text and "\u00b1 s.d." in text  # std only: no interval claimed
    # a map without loads or classical columns: maps, but no load or classical section
    table, traces, info, _ = fake_run(classical=False, loads=False, singles=False)
    doc, page = parse(write_report(tmp_path / "m.html", table, traces, {}))
    check_self_contained(doc, page)
    assert page.sections == ["run", "results", "maps", "gallery"]
    # only single traces, none flagged: nothing but the run and the table
    x, f = sawtooth(200, 1.0, 0)
    t = Trace(x, f, "one", "one.csv", {"line": 3})  # a line number alone is not a map
    table = ResultTable(rows=[{"trace": "one", "quality": "ok", "U0_eV": 1.0}])
    doc, page = parse(write_report(tmp_path / "s.html", table, [t], {}))
    check_self_contained(doc, page, images=False)
    assert page.sections == ["run", "results"]
    assert page.rows["results-table"] == 1


@pytest.fixture(scope="module")
def domain_report(tmp_path_factory) -> tuple[Path, ResultTable]:
    """A report with every section, in-domain verdicts included (written once)."""
    table, traces, info, overlays = fake_run(domain=True)
    path = tmp_path_factory.mktemp("report") / "report.html"
    return write_report(path, table, traces, info, overlays), table


def test_domain_columns_appear_only_when_present(domain_report):
    path, table = domain_report
    doc, page = parse(path)
    check_self_contained(doc, page)
    assert page.sections == ["run", "results", "maps", "load", "classical", "gallery"]
    text = " ".join(page.text)
    n_out = sum(1 for r in table.rows if r.get("in_domain") is False)
    assert n_out > 0 and f"{n_out} out of domain" in text
    assert "force range far beyond training" in text  # the reason, in table and gallery
    assert "in domain: green yes" in text  # the map's verdict strip
    assert "gallery" in page.sections


def test_text_is_escaped_and_gallery_is_capped(tmp_path):
    table, traces, info, overlays = fake_run(evil=True)
    info = dict(info, note=EVIL)
    doc, page = parse(
        write_report(tmp_path / "e.html", table, traces, info, overlays, max_gallery=1)
    )
    check_self_contained(doc, page)
    assert EVIL not in doc and html.escape(EVIL) in doc
    text = " ".join(page.text)
    assert "3 flagged traces, 1 shown" in text
    assert "2 more flagged traces not shown" in text
    assert len(re.findall(r'href="#g\d+"', doc)) == 1  # the table links the panel shown
    assert len(page.imgs) == 1 + 1 + 1 + 1  # map, load, classical, one gallery panel


@pytest.mark.slow
def test_a_2000_line_map_renders_in_seconds(tmp_path):
    table, traces, info, overlays = fake_run(map_lines=2000, singles=False)
    for r in table.rows[::50]:
        r["ppc_flag"] = 1
    write_report(tmp_path / "warm.html", *fake_run(map_lines=2)[:3])  # imports, fonts
    # CPU time of this process, not wall time: the machine may be shared
    t0 = time.process_time()
    out = write_report(tmp_path / "big.html", table, traces, info, overlays)
    assert time.process_time() - t0 < 15  # about 6 s on one core of a 2025 laptop
    doc, page = parse(out)
    check_self_contained(doc, page)
    assert page.rows["results-table"] == len(table)
    assert "more flagged traces not shown" in " ".join(page.text)


CHROMIUM = shutil.which("chromium") or (
    "/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None
)


@pytest.mark.skipif(
    CHROMIUM is None,
    reason="no chromium browser (Debian: apt-get install "
    "chromium); the headless rendering check needs one",
)
def test_renders_in_headless_chromium(domain_report, tmp_path):
    from matplotlib.image import imread

    page = domain_report[0]
    shot = tmp_path / "shot.png"
    cmd = [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        f"--user-data-dir={tmp_path / 'profile'}",
        f"--screenshot={shot}",
        "--window-size=1280,6000",  # the whole page, figures included
        page.resolve().as_uri(),
    ]
    try:
        subprocess.run(cmd, capture_output=True, timeout=120, check=False)
    except subprocess.TimeoutExpired:
        pytest.skip("chromium did not finish within 120 s")
    assert shot.exists(), "chromium wrote no screenshot"
    img = imread(shot)[..., :3]
    assert img.shape[:2] == (6000, 1280)
    # not blank: many pixels differ from the white background
    background = np.median(img.reshape(-1, 3), axis=0)
    assert background.min() > 0.9
    assert (np.abs(img - background).max(axis=2) > 0.1).mean() > 0.05
    # the embedded figures were decoded and drawn: only they hold strongly coloured
    # pixels (the style sheet's colours are pale, the text black or grey)
    saturation = img.max(axis=2) - img.min(axis=2)
    assert (saturation > 0.4).mean() > 0.01  # 0.02 with the figures, 0.0006 without
