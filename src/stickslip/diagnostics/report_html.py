"""One self-contained HTML report of a run (``--report PATH.html``).

:func:`write_report` turns a :class:`~stickslip.estimators.table.ResultTable`, the
traces behind its rows and a few facts about the run into a single HTML file that
opens offline: every figure is a PNG embedded as a ``data:`` URI, the style sheet is
inline, there is no script and nothing is fetched from the network. Sections:

- **Per-map answer** (where the table has map lines): the pooled <F>, U0, K and eta of
  each map, direction and load group with their 68 % / 95 % intervals, the between-line
  spread tau, the lines used and left out, and any change point along the slow scan
  axis (:mod:`stickslip.estimators.pooling`).
- **The run**: input files, the conditions used and where each came from, the
  estimator and its version, counts of rows (ok, flagged, unreadable, and out of
  domain where the table has an ``in_domain`` column), notes, the command line.
- **Results**: the table, a readable subset of columns first, every column in a
  collapsible ``<details>``.
- **Friction maps** (traces with ``line`` metadata, grouped by source file and
  channel): per direction, the lines stacked as a friction image (its colours scaled
  per direction) beside <F>, U0 and K (and the in-domain verdict where known) per scan
  line; change points drawn as dashed lines, lines left out of the map's answer marked.
- **Against load** (where rows carry a load): <F>, U0 and K of each line with its
  interval, and the mean per load.
- **Learned against classical** (where ``classical_*`` columns exist): parity of U0
  and K.
- **Flagged traces**: refused, PPC-flagged or out-of-domain traces with the model
  overlay where one is given (at most ``max_gallery`` panels; the rest are named).

A section appears only when the data for it exists; nothing is faked. All text from
the table, the traces and ``run_info`` is escaped.
"""

from __future__ import annotations

import base64
import html
import io
import math
import os
import textwrap
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from stickslip._version import __version__
from stickslip.atomic import write_text_atomic
from stickslip.conditions import QUANTITIES
from stickslip.estimators.table import OK, ResultTable, domain_verdict, is_missing, truthy

MAX_GALLERY = 24
FIG_DPI = 90
DIRECTION_ORDER = ("trace", "retrace", "loop")
TARGET_LABELS = {
    "F_mean_nN": "<F> (nN)",
    "U0_eV": "U0 (eV)",
    "K_N_m": "K (N/m)",
    "eta": "eta",
}
# the readable subset of the results table, in this order where present
READABLE = (
    "trace",
    "quality",
    "F_mean_nN",
    "U0_eV",
    "K_N_m",
    "eta",
    "classical_U0_eV",
    "classical_K_N_m",
    "gof",
    "ppc_flag",
    "in_domain",
    "domain_score",
    "domain_reason",
    "channel",
    "direction",
    "line",
    "load",
    "load_unit",
)
CONDITION_LABELS = {
    "lattice_nm": "lattice spacing a (nm)",
    "velocity_nm_per_s": "scan velocity v (nm/s)",
    "temperature_K": "temperature T (K)",
}
RUN_KEYS = (
    "files",
    "estimator",
    "model",
    "model_version",
    "version",
    "conditions",
    "counts",
    "command",
    "unreadable",
)

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;
margin:0 auto;max-width:1400px;padding:0 1.5em 3em;color:#1d1f21;line-height:1.4}
h1{margin:.6em 0 .2em}h2{border-bottom:2px solid #d0d4d9;padding-bottom:.2em;margin-top:1.6em}
h3{margin:1.2em 0 .4em;font-size:1.05em}
nav{position:sticky;top:0;background:#fff;padding:.4em 0;border-bottom:1px solid #e3e6ea}
nav a{margin-right:1.2em;color:#1f5fa8;text-decoration:none}
table{border-collapse:collapse;font-size:.82em;margin:.4em 0}
th,td{border:1px solid #d6dae0;padding:.15em .45em;text-align:left;vertical-align:top}
thead th{background:#eef1f5;position:sticky;top:0}
td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
tr.flagged td{background:#fdecea}tr.unreadable td{background:#eceff1;color:#555}
tr.ood td{background:#fff4e0}td.reason{min-width:16em}
.scroll{max-height:32em;overflow:auto;border:1px solid #e3e6ea}
.counts span{display:inline-block;margin:0 .5em .3em 0;padding:.15em .6em;border-radius:.8em;
background:#eef1f5}.counts .ok{background:#e3f4e6}.counts .bad{background:#fdecea}
.counts .grey{background:#e0e3e6}.counts .warn{background:#fff1d6}
img{max-width:100%;height:auto;display:block;margin:.3em 0}
.gallery{display:grid;grid-template-columns:repeat(auto-fill,minmax(520px,1fr));gap:.8em}
.gallery figure{margin:0;border:1px solid #e3e6ea;padding:.3em}
figcaption,.caption{font-size:.85em;color:#444}
code{background:#f3f4f6;padding:0 .25em;word-break:break-all}
details summary{cursor:pointer;color:#1f5fa8;margin:.5em 0}
"""


def write_report(
    path: str | os.PathLike,
    table: ResultTable,
    traces: Sequence[Any],
    run_info: Mapping[str, Any],
    overlays: Mapping[str, np.ndarray] | None = None,
    *,
    max_gallery: int = MAX_GALLERY,
    groups: Sequence[Mapping[str, Any]] | None = None,
) -> Path:
    """Write the run's report as one self-contained HTML file, atomically.

    Parameters
    ----------
    path : path-like
        The HTML file to write.
    table : ResultTable
        The result table of the run, one row per trace or unreadable input.
    traces : sequence of Trace
        The traces behind the rows, in the order of the rows that came from a trace
        (rows of unreadable inputs have none). A row and a trace are paired when the
        row's ``trace`` is the trace's ``name``; a table with as many rows as traces
        is paired by position.
    run_info : mapping
        Facts about the run, every key optional: ``files`` (input paths),
        ``estimator`` / ``model`` (name), ``model_version``, ``version`` (of
        stickslip; the installed one by default), ``conditions`` (quantity -> value,
        ``(value, source)`` or ``{"value": .., "source": ..}``), ``counts`` (label ->
        number, shown as given), ``command`` (str or list of str), ``unreadable``
        (``(path, reason)`` pairs or path -> reason). Other keys with plain values
        are listed as they are.
    overlays : mapping of str to ndarray, optional
        Trace name -> replicate force in nN (the PT model at the estimate, from a
        posterior predictive check), drawn over the trace in the gallery.
    max_gallery : int
        Most panels in the gallery of flagged traces; the others are named.
    groups : sequence of mapping, optional
        The per-map pooled answer (rows of the groups table,
        :func:`stickslip.estimators.pooling.pool_groups`): shown first, and its change
        points drawn on the maps.

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    rows = _row_infos(table, traces)
    has_domain = "in_domain" in table.columns
    flagged = [r for r in rows if r.trace is not None and r.flagged]
    in_gallery = {r.index for r in flagged[: max(max_gallery, 0)]}
    sections: list[tuple[str, str, str]] = []
    if groups:
        sections.append(("answer", "Per-map answer", _groups_section(groups)))
    sections += [
        ("run", "The run", _run_section(table, rows, run_info, has_domain)),
        ("results", "Results", _table_section(table, rows, in_gallery)),
    ]
    maps = _map_groups(rows)
    if maps:
        sections.append(("maps", "Friction maps",
                         _maps_section(maps, table, has_domain, groups or ())))
    if _load_rows(rows):
        sections.append(("load", "Against load", _load_section(rows)))
    if _classical_pairs(rows):
        sections.append(("classical", "Learned against classical", _classical_section(rows)))
    if flagged:
        sections.append(
            (
                "gallery",
                "Flagged traces",
                _gallery_section(flagged, table, overlays or {}, max_gallery),
            )
        )
    title = f"stickslip report: {_estimator_name(table, run_info) or 'run'}"
    nav = "".join(f'<a href="#{sid}">{_esc(name)}</a>' for sid, name, _ in sections)
    body = "\n".join(
        f'<section id="{sid}">\n<h2>{_esc(name)}</h2>\n{content}\n</section>'
        for sid, name, content in sections
    )
    doc = (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        f"<title>{_esc(title)}</title>\n<style>{CSS}</style>\n</head>\n<body>\n"
        f"<h1>{_esc(title)}</h1>\n<nav>{nav}</nav>\n{body}\n"
        f'<p class="caption">Written by stickslip {_esc(__version__)}. '
        "Self-contained: no script, nothing loaded from the network.</p>\n"
        "</body>\n</html>\n"
    )
    write_text_atomic(path, doc)
    return path


# --------------------------------------------------------------------------- rows


@dataclass
class _Row:
    """One table row with its trace (None for an unreadable input) and its status."""

    index: int
    row: Mapping[str, Any]
    trace: Any
    refused: bool
    ppc: bool
    out_of_domain: bool | None  # None: unknown or no domain column

    @property
    def unreadable(self) -> bool:
        return self.trace is None and self.row.get("quality") != OK

    @property
    def flagged(self) -> bool:
        return self.refused or self.ppc or bool(self.out_of_domain)

    @property
    def name(self) -> str:
        return str(self.row.get("trace") or (self.trace.name if self.trace is not None else ""))

    def value(self, key: str) -> float:
        return _num(self.row.get(key))

    def reasons(self) -> list[str]:
        out = []
        if self.refused:
            out.append(f"no estimate: {self.row.get('quality')}")
        if self.ppc:
            gof = self.value("gof")
            out.append("PPC flag" + (f" (gof = {gof:.2f})" if math.isfinite(gof) else ""))
        if self.out_of_domain:
            why = self.row.get("domain_reason")
            score = self.value("domain_score")
            text = "out of domain"
            if not is_missing(why) and str(why):
                text += f": {why}"
            if math.isfinite(score):
                text += f" (score {score:.3g})"
            out.append(text)
        return out


def _row_infos(table: ResultTable, traces: Sequence[Any]) -> list[_Row]:
    """Pair rows with traces and classify each row."""
    pairing = _pair(table.rows, traces)
    out = []
    for i, (row, j) in enumerate(zip(table.rows, pairing, strict=True)):
        trace = traces[j] if j is not None else None
        quality = row.get("quality")
        dom = domain_verdict(row)
        out.append(
            _Row(
                index=i,
                row=row,
                trace=trace,
                refused=trace is not None and quality != OK,
                ppc=quality == OK and truthy(row.get("ppc_flag")),
                out_of_domain=None if dom is None else not dom,
            )
        )
    return out


def _pair(rows: Sequence[Mapping[str, Any]], traces: Sequence[Any]) -> list[int | None]:
    """Trace index of each row (None where the row has no trace)."""
    out: list[int | None] = [None] * len(rows)
    j = 0
    for i, r in enumerate(rows):
        if j < len(traces) and str(r.get("trace")) == getattr(traces[j], "name", None):
            out[i] = j
            j += 1
    if j == len(traces):
        return out
    if len(rows) == len(traces):  # names differ from the table's: trust the order
        return list(range(len(rows)))
    # leftovers: match by name among the traces not yet paired
    used = {k for k in out if k is not None}
    free: dict[str, list[int]] = {}
    for k, t in enumerate(traces):
        if k not in used:
            free.setdefault(getattr(t, "name", ""), []).append(k)
    for i, r in enumerate(rows):
        if out[i] is None and free.get(str(r.get("trace"))):
            out[i] = free[str(r.get("trace"))].pop(0)
    return out


def _num(value: Any) -> float:
    if isinstance(value, (bool, np.bool_)) or value is None:
        return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


# --------------------------------------------------------------------------- html


def _esc(value: Any) -> str:
    return html.escape(str(value), quote=True)


def _fmt(value: Any) -> str:
    if is_missing(value):
        return ""
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.4g}"
    if isinstance(value, np.integer):
        return str(int(value))
    return str(value)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_)
    )


def _td(value: Any) -> str:
    cls = ' class="num"' if _is_number(value) else ""
    return f"<td{cls}>{_esc(_fmt(value))}</td>"


def _kv_table(pairs: Iterable[tuple[str, str]]) -> str:
    """Two-column table of already escaped (label, html) pairs."""
    body = "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in pairs)
    return f'<table class="kv"><tbody>{body}</tbody></table>' if body else ""


def _png_uri(fig: Any, dpi: int = FIG_DPI) -> str:
    """The figure as a ``data:image/png;base64,`` URI (figure closed)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _img(uri: str, alt: str) -> str:
    return f'<img src="{uri}" alt="{_esc(alt)}">'


def _figure(
    width_in: float,
    height_in: float,
    margins_in: tuple[float, float, float, float] = (0.8, 0.25, 0.45, 0.6),
    wspace: float = 0.3,
    hspace: float = 0.3,
) -> Any:
    """A matplotlib figure drawn by the Agg canvas (no pyplot, no display).

    Margins (left, right, top, bottom) are fixed in inches: an automatic layout engine
    would draw every figure twice.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in))
    FigureCanvasAgg(fig)
    left, right, top, bottom = margins_in
    fig.subplots_adjust(
        left=left / width_in,
        right=1 - right / width_in,
        top=1 - top / height_in,
        bottom=bottom / height_in,
        wspace=wspace,
        hspace=hspace,
    )
    return fig


# --------------------------------------------------------------------------- the run


def _estimator_name(table: ResultTable, run_info: Mapping[str, Any]) -> str:
    for key in ("model", "estimator"):
        if run_info.get(key):
            return str(run_info[key])
    if table.estimator:
        return table.estimator
    names = {str(r.get("estimator")) for r in table.rows if r.get("estimator")}
    return ", ".join(sorted(names))


def _run_section(
    table: ResultTable, rows: Sequence[_Row], info: Mapping[str, Any], has_domain: bool
) -> str:
    parts = []
    # counts
    n_ok = sum(1 for r in rows if r.row.get("quality") == OK and not r.flagged)
    n_flag = sum(1 for r in rows if r.refused or r.ppc)
    n_unread = sum(1 for r in rows if r.unreadable)
    chips = [
        ("", f"{len(rows)} rows"),
        ("ok", f"{n_ok} ok"),
        (
            "bad",
            f"{n_flag} flagged ({sum(r.refused for r in rows)} without estimate, "
            f"{sum(r.ppc for r in rows)} PPC)",
        ),
        ("grey", f"{n_unread} unreadable"),
    ]
    if has_domain:
        n_out = sum(1 for r in rows if r.out_of_domain)
        n_unknown = sum(1 for r in rows if r.out_of_domain is None and not r.unreadable)
        chips.append(
            ("warn", f"{n_out} out of domain" + (f" ({n_unknown} not judged)" if n_unknown else ""))
        )
    parts.append(
        '<p class="counts" id="counts">'
        + "".join(f'<span class="{c}">{_esc(t)}</span>' for c, t in chips)
        + "</p>"
    )
    parts.append(
        '<p class="caption">ok: an estimate that is not flagged'
        + (" and not out of domain" if has_domain else "")
        + "; flagged: no estimate for a readable trace, or a failed posterior "
        "predictive check (PPC).</p>"
    )
    # estimator and version
    pairs = []
    name = _estimator_name(table, info)
    if name:
        pairs.append(("estimator", _esc(name)))
    if info.get("model_version") is not None:
        pairs.append(("model version", _esc(info["model_version"])))
    pairs.append(("stickslip version", _esc(info.get("version") or __version__)))
    if info.get("counts"):
        counts = info["counts"]
        if isinstance(counts, Mapping):
            pairs.append(("counts (run)", _esc(", ".join(f"{k}: {v}" for k, v in counts.items()))))
    command = info.get("command")
    if command:
        text = " ".join(str(c) for c in command) if not isinstance(command, str) else command
        pairs.append(("command", f"<code>{_esc(text)}</code>"))
    for k, v in info.items():
        if k in RUN_KEYS or isinstance(v, (Mapping, list, tuple, set, np.ndarray)):
            continue
        pairs.append((_esc(k), _esc(_fmt(v))))
    parts.append(_kv_table(pairs))
    # conditions
    parts.append("<h3>Conditions and their sources</h3>")
    parts.append(_conditions_html(table, info))
    # files
    files = [str(f) for f in info.get("files") or []]
    if not files:
        files = list(dict.fromkeys(str(r.row["file"]) for r in rows if r.row.get("file")))
    if files:
        items = "".join(f"<li><code>{_esc(f)}</code></li>" for f in files)
        parts.append(f"<h3>Input files ({len(files)})</h3><ul>{items}</ul>")
    # unreadable inputs
    unread = _unreadable(info, rows)
    if unread:
        items = "".join(f"<li><code>{_esc(f)}</code>: {_esc(why)}</li>" for f, why in unread)
        parts.append(f"<h3>Unreadable inputs ({len(unread)})</h3><ul>{items}</ul>")
    if table.notes:
        items = "".join(f"<li>{_esc(n)}</li>" for n in table.notes)
        parts.append(f"<h3>Notes</h3><ul>{items}</ul>")
    return "\n".join(parts)


def _conditions_html(table: ResultTable, info: Mapping[str, Any]) -> str:
    """Values of each condition used in the table, with source and count of rows."""
    given = info.get("conditions") or {}
    body = []
    for q in QUANTITIES:
        src_col = q.split("_")[0] + "_source"
        seen: dict[tuple[str, str], int] = {}
        for r in table.rows:
            if is_missing(r.get(q)):
                continue
            key = (_fmt(r.get(q)), _fmt(r.get(src_col)) or "not recorded")
            seen[key] = seen.get(key, 0) + 1
        for (value, source), n in sorted(seen.items()):
            body.append(
                f'<tr><td>{_esc(CONDITION_LABELS.get(q, q))}</td><td class="num">'
                f'{_esc(value)}</td><td>{_esc(source)}</td><td class="num">{n}</td>'
                "</tr>"
            )
    for q, v in given.items():  # as the run states them (e.g. the flags given)
        if isinstance(v, Mapping):
            value, source = v.get("value"), v.get("source", "")
        elif isinstance(v, (tuple, list)) and len(v) == 2:
            value, source = v
        else:
            value, source = v, ""
        body.append(
            f'<tr><td>{_esc(CONDITION_LABELS.get(q, q))}</td><td class="num">'
            f"{_esc(_fmt(value))}</td><td>{_esc(_fmt(source) or 'run')}</td>"
            "<td>(run)</td></tr>"
        )
    if not body:
        return "<p>No conditions recorded.</p>"
    return (
        "<table><thead><tr><th>condition</th><th>value</th><th>source</th><th>rows</th>"
        f"</tr></thead><tbody>{''.join(body)}</tbody></table>"
        '<p class="caption">Sources: <b>flag</b> given by the user, <b>file</b> read '
        "from the trace file, <b>model</b> the estimator's reference.</p>"
    )


def _unreadable(info: Mapping[str, Any], rows: Sequence[_Row]) -> list[tuple[str, str]]:
    listed = info.get("unreadable") or []
    if isinstance(listed, Mapping):
        out = [(str(k), str(v)) for k, v in listed.items()]
    else:
        out = []
        for item in listed:
            if isinstance(item, Mapping):
                out.append(
                    (str(item.get("file", item.get("path", ""))), str(item.get("reason", "")))
                )
            elif isinstance(item, (tuple, list)) and len(item) == 2:
                out.append((str(item[0]), str(item[1])))
            else:
                out.append((str(item), ""))
    known = {f for f, _ in out}
    for r in rows:
        if r.unreadable:
            f = str(r.row.get("file") or r.name)
            if f not in known:
                out.append((f, str(r.row.get("quality") or "")))
                known.add(f)
    return out


# --------------------------------------------------------------------------- table


def _row_class(r: _Row) -> str:
    if r.unreadable:
        return ' class="unreadable"'
    if r.refused or r.ppc:
        return ' class="flagged"'
    if r.out_of_domain:
        return ' class="ood"'
    return ""


def _estimate_cell(row: Mapping[str, Any], key: str, level: str | None) -> str:
    v = row.get(key)
    text = _fmt(v)
    if text and level:
        lo, hi = row.get(f"{key}_lo{level}"), row.get(f"{key}_hi{level}")
        if not (is_missing(lo) or is_missing(hi)):
            text += f" [{_fmt(lo)}, {_fmt(hi)}]"
    elif text and not is_missing(row.get(f"{key}_std")):
        text += f" \u00b1 {_fmt(row.get(f'{key}_std'))}"
    cls = ' class="num"' if text else ""
    return f"<td{cls}>{_esc(text)}</td>"


def _table_section(table: ResultTable, rows: Sequence[_Row], in_gallery: set[int]) -> str:
    cols = table.columns
    level = "95" if table.intervals or "U0_eV_lo95" in cols else None
    show = [c for c in READABLE if c in cols]
    heads = []
    for c in show:
        label = TARGET_LABELS.get(c, c)
        if c in TARGET_LABELS:
            if level:
                label += f" [{level} %]"
            elif f"{c}_std" in cols:
                label += " \u00b1 s.d."
        heads.append(f"<th>{_esc(label)}</th>")
    body = []
    for r in rows:
        cells = []
        for c in show:
            if c in TARGET_LABELS:
                cells.append(_estimate_cell(r.row, c, level))
            elif c == "trace" and r.index in in_gallery:  # a link to its panel
                cells.append(f'<td><a href="#g{r.index}">{_esc(r.name)}</a></td>')
            elif c in ("quality", "domain_reason"):
                cells.append(f'<td class="reason">{_esc(_fmt(r.row.get(c)))}</td>')
            else:
                cells.append(_td(r.row.get(c)))
        body.append(f"<tr{_row_class(r)}>{''.join(cells)}</tr>")
    readable = (
        f'<div class="scroll"><table id="results-table"><thead><tr>{"".join(heads)}'
        f"</tr></thead><tbody>{''.join(body)}</tbody></table></div>"
    )
    caption = (
        f'<p class="caption">{len(rows)} rows. '
        + (f"Estimates with their central {level} % interval. " if level else "")
        + "Red: flagged; grey: unreadable input"
        + ("; orange: out of domain" if "in_domain" in cols else "")
        + ".</p>"
    )
    full_body = "".join(
        f"<tr{_row_class(r)}>{''.join(_td(r.row.get(c)) for c in cols)}</tr>" for r in rows
    )
    full = (
        f"<details><summary>All {len(cols)} columns</summary>"
        f'<div class="scroll"><table id="full-table"><thead><tr>'
        f"{''.join(f'<th>{_esc(c)}</th>' for c in cols)}</tr></thead>"
        f"<tbody>{full_body}</tbody></table></div></details>"
    )
    return caption + readable + full


# --------------------------------------------------------------------------- maps


def _line_of(trace: Any) -> int | None:
    line = (getattr(trace, "meta", None) or {}).get("line")
    if isinstance(line, (bool, np.bool_)) or not isinstance(line, (int, np.integer)):
        return None
    return int(line)


def _map_groups(rows: Sequence[_Row]) -> dict[tuple[str, str], list[_Row]]:
    """Rows whose trace has a line number, by (source file, channel); maps of >= 2 lines."""
    groups: dict[tuple[str, str], list[_Row]] = {}
    for r in rows:
        if r.trace is None or _line_of(r.trace) is None:
            continue
        key = (
            str(r.trace.source or r.row.get("file") or ""),
            str(r.trace.meta.get("channel") or ""),
        )
        groups.setdefault(key, []).append(r)
    return {k: g for k, g in groups.items() if len({_line_of(r.trace) for r in g}) >= 2}


def _directions(group: Sequence[_Row]) -> list[str]:
    found = list(dict.fromkeys(str(r.trace.meta.get("direction") or "") for r in group))
    return sorted(
        found,
        key=lambda d: (
            DIRECTION_ORDER.index(d) if d in DIRECTION_ORDER else len(DIRECTION_ORDER),
            d,
        ),
    )


def _interval(r: _Row, key: str) -> tuple[float, float, str]:
    """68 % interval of an estimate, else +- one standard deviation, else NaN."""
    lo, hi = r.value(f"{key}_lo68"), r.value(f"{key}_hi68")
    if math.isfinite(lo) and math.isfinite(hi):
        return lo, hi, "68 % interval"
    v, s = r.value(key), r.value(f"{key}_std")
    if math.isfinite(v) and math.isfinite(s):
        return v - s, v + s, "\u00b11 s.d."
    return math.nan, math.nan, ""


def _changes(pooled: Sequence[Mapping[str, Any]], source: str, channel: str
             ) -> dict[str, list[int]]:  # fmt: skip
    """Change lines of a map's groups, per direction (``both`` counts for each)."""
    out: dict[str, list[int]] = {}
    for g in pooled:
        line = g.get("change_line")
        if g.get("segment") != "all" or is_missing(line) or line is None:
            continue
        if str(g.get("file") or "") != source or str(g.get("channel") or "") != channel:
            continue
        dirs = DIRECTION_ORDER[:2] if g.get("direction") == "both" else (str(g["direction"]),)
        for d in dirs:
            out.setdefault(d, [])
            if int(line) not in out[d]:
                out[d].append(int(line))
    return out


def _groups_section(pooled: Sequence[Mapping[str, Any]]) -> str:
    """The per-map answer: one table row per group, value [95 %] (68 %) and tau."""
    keys = ("F_mean_nN", "U0_eV", "K_N_m", "eta")
    head = ["group", "direction", "segment", "lines", "used", "left out"]
    head += [f"{TARGET_LABELS[k]} [95 %] (68 %)" for k in keys]
    head += [f"tau {k.split('_')[0]}" for k in keys] + ["change line"]
    body = []
    for g in pooled:
        cells = [_td(g.get(c)) for c in ("group", "direction", "segment", "lines", "n_lines",
                                         "n_left_out")]  # fmt: skip
        for k in keys:
            v, lo, hi, lo68, hi68 = (_num(g.get(c)) for c in
                                     (k, f"{k}_lo95", f"{k}_hi95", f"{k}_lo68", f"{k}_hi68"))
            text = (f"{v:.4g} [{lo:.3g}, {hi:.3g}] ({lo68:.3g}, {hi68:.3g})"
                    if math.isfinite(v) else "")  # fmt: skip
            cells.append(f'<td class="num">{_esc(text)}</td>')
        for k in keys:
            t, tlo, thi = (_num(g.get(c)) for c in (f"{k}_tau", f"{k}_tau_lo95", f"{k}_tau_hi95"))
            text = f"{t:.3g} [{tlo:.2g}, {thi:.2g}]" if math.isfinite(t) else ""
            cells.append(f'<td class="num">{_esc(text)}</td>')
        cells.append(_td(g.get("change_line")))
        body.append("<tr>" + "".join(cells) + "</tr>")
    table = ("<div class=\"scroll\"><table><thead><tr>"
             + "".join(f"<th>{_esc(h)}</th>" for h in head)
             + "</tr></thead><tbody>" + "\n".join(body) + "</tbody></table></div>")  # fmt: skip
    caption = (
        "One answer per map, scan direction and load group: the lines' estimates pooled by "
        "a random-effects model (REML) on their own intervals (U0, K and eta on a log scale), "
        "with a systematic floor for the errors all lines of a map share (tip, stated "
        "conditions, calibration, an offset per scan direction), calibrated on simulated "
        "maps. 'both': trace and retrace together (an offset that does not reverse cancels). "
        "tau: the spread between lines (log units for U0, K, eta: a relative spread; nN for "
        "<F>) with its 95 % Q-profile interval. 'left out': lines without an estimate, out "
        "of domain, outside their map's predictive interval, or showing what the map's other "
        "lines do not (spikes, a defect: map_reason). Where the lines "
        "change along the slow scan axis (a tip change, a domain) the change line is given "
        "and each side is pooled on its own (before / after).")
    return table + f'\n<p class="caption">{_esc(caption)}</p>'


def _maps_section(
    groups: Mapping[tuple[str, str], list[_Row]], table: ResultTable, has_domain: bool,
    pooled: Sequence[Mapping[str, Any]] = (),
) -> str:
    parts = []
    for (source, channel), group in groups.items():
        dirs = _directions(group)
        lines = sorted({_line_of(r.trace) for r in group})
        title = Path(source).name or "(no file)"
        if channel:
            title += f" \u2014 {channel}"
        file = str(group[0].row.get("file") or source)
        uri, caption = _map_figure(group, dirs, lines, has_domain,
                                   _changes(pooled, file, channel))
        parts.append(f"<h3>{_esc(title)}</h3>")
        parts.append(_img(uri, f"friction map {title}: image and estimates per line"))
        parts.append(f'<p class="caption">{_esc(caption)}</p>')
    return "\n".join(parts)


def _map_figure(
    group: Sequence[_Row], dirs: Sequence[str], lines: Sequence[int], has_domain: bool,
    changes: Mapping[str, Sequence[int]] | None = None,
) -> tuple[str, str]:
    from matplotlib import transforms
    from matplotlib.colors import to_rgb

    l0, l1 = lines[0], lines[-1]
    n_lines = l1 - l0 + 1
    keys = ("F_mean_nN", "U0_eV", "K_N_m")
    ncols = 1 + len(keys) + (1 if has_domain else 0)
    ratios = [3.2, 1.2, 1.2, 1.2] + ([0.35] if has_domain else [])
    fig = _figure(14.0, 3.0 * len(dirs) + 1.2, (0.85, 0.2, 0.6, 0.6), wspace=0.18, hspace=0.12)
    axes = fig.subplots(
        len(dirs), ncols, squeeze=False, sharey=True, gridspec_kw={"width_ratios": ratios}
    )
    unit = str(group[0].trace.meta.get("unit") or "nN")
    x_px = group[0].trace.meta.get("x_unit") == "px"
    changes = changes or {}
    level = ""
    n_px = max(int(np.asarray(r.trace.force_nN).size) for r in group)
    for d_i, direction in enumerate(dirs):
        sub = [r for r in group if str(r.trace.meta.get("direction") or "") == direction]
        # each direction its own colour scale: a real map's trace and retrace differ by
        # twice the offset, and one shared scale leaves each image one flat colour
        forces = np.concatenate([np.asarray(r.trace.force_nN, float).ravel() for r in sub])
        forces = forces[np.isfinite(forces)]
        vmin, vmax = np.percentile(forces, [1, 99]) if forces.size else (0.0, 1.0)
        image = np.full((n_lines, n_px), np.nan)
        x_max = 0.0
        for r in sub:
            f = np.asarray(r.trace.force_nN, float)
            if direction == "retrace":  # back to sample x order, beside the trace image
                f = f[::-1]
            image[_line_of(r.trace) - l0, : f.size] = f
            x = np.asarray(r.trace.x_nm, float)
            x_max = max(x_max, float(x[-1] - x[0]) * f.size / max(f.size - 1, 1))
        ax = axes[d_i, 0]
        for c in changes.get(direction, ()):
            ax.axhline(c - 0.5, color="w", ls="--", lw=1.0)
        im = ax.imshow(
            image,
            aspect="auto",
            cmap="viridis",
            vmin=vmin,
            vmax=vmax,
            extent=(0.0, x_max or n_px, l1 + 0.5, l0 - 0.5),
            interpolation="nearest",
        )
        fig.colorbar(im, ax=ax, pad=0.01, fraction=0.04)
        ax.set_ylabel(f"{direction or 'line'}: scan line")
        if d_i == len(dirs) - 1:
            ax.set_xlabel("x (pixel)" if x_px else "x (nm)")
        if d_i == 0:
            ax.set_title(f"friction image, F ({unit})")
        by_line = {_line_of(r.trace): r for r in sub}
        ys = np.array(sorted(by_line))
        for k_i, key in enumerate(keys):
            ax = axes[d_i, 1 + k_i]
            vals = np.array([by_line[y].value(key) for y in ys])
            bounds = [_interval(by_line[y], key) for y in ys]
            lo = np.array([b[0] for b in bounds])
            hi = np.array([b[1] for b in bounds])
            level = level or next((b[2] for b in bounds if b[2]), "")
            if np.isfinite(lo).any():
                ax.fill_betweenx(ys, lo, hi, color="C0", alpha=0.25, lw=0, step="mid")
            style = "-" if ys.size > 60 else ".-"
            ax.plot(vals, ys, style, color="C0", lw=0.9, ms=4)
            if key == "F_mean_nN":  # the plain mean of each line, for comparison
                means = [float(np.mean(by_line[y].trace.force_nN)) for y in ys]
                ax.plot(means, ys, "-", color="0.5", lw=0.7, label="line mean")
            for c in changes.get(direction, ()):
                ax.axhline(c - 0.5, color="C1", ls="--", lw=1.0,
                           label="change point" if k_i == 0 else None)
            apart = np.array([not is_missing(by_line[y].row.get("map_reason"))
                              and by_line[y].row.get("map_reason") is not None
                              for y in ys], bool)  # fmt: skip
            if apart.any():
                ax.plot(vals[apart], ys[apart], "o", mfc="none", color="C1", ms=6,
                        label="left out of the map's answer")
            bad = np.array([by_line[y].refused or by_line[y].ppc for y in ys], bool)
            if bad.any():
                tr = transforms.blended_transform_factory(ax.transAxes, ax.transData)
                ax.plot(
                    np.full(int(bad.sum()), 0.03),
                    ys[bad],
                    "x",
                    color="C3",
                    ms=5,
                    transform=tr,
                    label="flagged",
                )
            ax.grid(alpha=0.3)
            if d_i == 0:
                ax.set_title(TARGET_LABELS[key])
            if d_i == len(dirs) - 1:
                ax.set_xlabel(TARGET_LABELS[key])
            if key == "F_mean_nN" and d_i == 0 and ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=7, loc="lower right")
        if has_domain:
            ax = axes[d_i, -1]
            colours = np.full((n_lines, 1, 3), to_rgb("0.85"))
            for y, r in by_line.items():
                if r.out_of_domain is not None:
                    colours[y - l0, 0] = to_rgb("C3" if r.out_of_domain else "C2")
            ax.imshow(
                colours, aspect="auto", extent=(0, 1, l1 + 0.5, l0 - 0.5), interpolation="nearest"
            )
            ax.set_xticks([])
            if d_i == 0:
                ax.set_title("in domain", fontsize=9)
    axes[0, 0].set_ylim(l1 + 0.5, l0 - 0.5)
    fig.text(
        0.99,
        0.995,
        f"estimates per scan line; shaded: {level or 'no interval given'}",
        ha="right",
        va="top",
        fontsize=9,
    )
    n_dir = {
        d: sum(1 for r in group if str(r.trace.meta.get("direction") or "") == d) for d in dirs
    }
    caption = (
        f"{len(lines)} scan lines (lines {l0}-{l1}), "
        + ", ".join(f"{n} {d or 'undirected'}" for d, n in n_dir.items())
        + f", {n_px} pixels per line. Left: the lines stacked as an image (colour scale "
        "1st-99th percentile of each direction's lines"
        + ("; retrace lines drawn in sample x order, sign as friction" if "retrace" in dirs else "")
        + "). Right: estimates per line, "
        + (f"shaded {level}" if level else "no intervals")
        + "; grey: plain mean of the line; red x: flagged line; orange circle: a line "
        "left out of the per-map answer (inconsistent with its map, or unlike its other lines: "
        "map_reason); dashed: change point "
        "along the slow scan axis"
        + ("; in domain: green yes, red no, grey not judged" if has_domain else "")
        + "."
    )
    return _png_uri(fig), caption


# --------------------------------------------------------------------------- load


def _load_rows(rows: Sequence[_Row]) -> list[_Row]:
    """Rows with an estimate and a numeric load."""
    return [
        r
        for r in rows
        if r.row.get("quality") == OK
        and math.isfinite(r.value("load"))
        and any(math.isfinite(r.value(k)) for k in ("F_mean_nN", "U0_eV", "K_N_m"))
    ]


def _load_section(rows: Sequence[_Row]) -> str:
    sel = _load_rows(rows)
    keys = ("F_mean_nN", "U0_eV", "K_N_m")
    unit = next((str(r.row["load_unit"]) for r in sel if r.row.get("load_unit")), "")
    loads = np.array([r.value("load") for r in sel])
    groups = sorted(set(loads.tolist()))
    dirs = list(dict.fromkeys(str(r.row.get("direction") or "") for r in sel))
    fig = _figure(14.0, 3.8, (0.8, 0.2, 0.5, 0.6), wspace=0.3)
    axes = fig.subplots(1, len(keys), squeeze=False)[0]
    span = (max(groups) - min(groups)) if len(groups) > 1 else 1.0
    offsets = {d: (i - (len(dirs) - 1) / 2) * 0.012 * span for i, d in enumerate(dirs)}
    level = ""
    summary: list[tuple[float, int, list[tuple[float, float]]]] = []
    for g in groups:
        members = [r for r in sel if r.value("load") == g]
        stats = []
        for key in keys:
            v = np.array([r.value(key) for r in members])
            v = v[np.isfinite(v)]
            stats.append(
                (
                    float(v.mean()) if v.size else math.nan,
                    float(v.std(ddof=1)) if v.size > 1 else math.nan,
                )
            )
        summary.append((g, len(members), stats))
    for ax, key in zip(axes, keys, strict=True):
        for i, d in enumerate(dirs):
            sub = [r for r in sel if str(r.row.get("direction") or "") == d]
            x = np.array([r.value("load") for r in sub]) + offsets[d]
            y = np.array([r.value(key) for r in sub])
            bounds = [_interval(r, key) for r in sub]
            level = level or next((b[2] for b in bounds if b[2]), "")
            lo = np.array([b[0] for b in bounds])
            hi = np.array([b[1] for b in bounds])
            yerr = np.vstack([np.clip(y - lo, 0, None), np.clip(hi - y, 0, None)])
            yerr = np.where(np.isfinite(yerr), yerr, 0.0)
            ax.errorbar(
                x, y, yerr=yerr, fmt="o", ms=3, lw=0.6, alpha=0.5, color=f"C{i}", label=d or "lines"
            )
        g_x = np.array([s[0] for s in summary])
        j = keys.index(key)
        means = np.array([s[2][j][0] for s in summary])
        sds = np.nan_to_num(np.array([s[2][j][1] for s in summary]))
        ax.errorbar(
            g_x,
            means,
            yerr=sds,
            fmt="s-",
            color="k",
            ms=5,
            capsize=4,
            lw=1.2,
            label="mean \u00b1 s.d. over lines",
        )
        ax.set_xlabel(f"load ({unit})" if unit else "load")
        ax.set_ylabel(TARGET_LABELS[key])
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(
        f"Estimates against load (bars on each line: {level or 'none given'})", fontsize=10
    )
    heads = "".join(f"<th>{_esc(TARGET_LABELS[k])} mean \u00b1 s.d.</th>" for k in keys)
    body = "".join(
        f'<tr><td class="num">{_esc(_fmt(g))}</td><td class="num">{n}</td>'
        + "".join(
            f'<td class="num">{_esc(_fmt(m))}'
            + (f" \u00b1 {_esc(_fmt(s))}" if math.isfinite(s) else "")
            + "</td>"
            for m, s in stats
        )
        + "</tr>"
        for g, n, stats in summary
    )
    n_without = sum(1 for r in rows if r.row.get("quality") == OK) - len(sel)
    note = f" {n_without} rows with an estimate have no load." if n_without else ""
    return (
        _img(_png_uri(fig), "estimates against load")
        + f'<p class="caption">{len(sel)} estimates at {len(groups)} loads; each with its '
        f"{_esc(level or 'estimate (no interval given)')}, per load the mean and the spread "
        f"over them.{_esc(note)}</p>"
        + f"<table><thead><tr><th>load ({_esc(unit)})</th><th>lines</th>{heads}</tr></thead>"
        f"<tbody>{body}</tbody></table>"
    )


# --------------------------------------------------------------------------- classical


def _classical_pairs(rows: Sequence[_Row]) -> dict[str, list[_Row]]:
    """Per U0 / K, the rows with both the learned and the classical value."""
    out = {}
    for key in ("U0_eV", "K_N_m"):
        sel = [
            r
            for r in rows
            if r.row.get("quality") == OK
            and math.isfinite(r.value(key))
            and math.isfinite(r.value(f"classical_{key}"))
        ]
        if sel:
            out[key] = sel
    return out


def _classical_section(rows: Sequence[_Row]) -> str:
    pairs = _classical_pairs(rows)
    fig = _figure(5.2 * len(pairs), 4.6, (0.8, 0.2, 0.4, 0.6), wspace=0.35)
    axes = fig.subplots(1, len(pairs), squeeze=False)[0]
    level = ""
    summary = []
    for ax, (key, sel) in zip(axes, pairs.items(), strict=True):
        x = np.array([r.value(f"classical_{key}") for r in sel])
        y = np.array([r.value(key) for r in sel])
        bounds = [_interval(r, key) for r in sel]
        level = level or next((b[2] for b in bounds if b[2]), "")
        lo = np.array([b[0] for b in bounds])
        hi = np.array([b[1] for b in bounds])
        yerr = np.where(np.isfinite([y - lo, hi - y]), np.clip([y - lo, hi - y], 0, None), 0.0)
        good = np.array([str(r.row.get("classical_quality", OK)) in (OK, "None", "") for r in sel])
        if good.any():
            ax.errorbar(
                x[good],
                y[good],
                yerr=yerr[:, good],
                fmt="o",
                ms=3.5,
                lw=0.6,
                alpha=0.7,
                color="C0",
                label="classical ok",
            )
        if (~good).any():
            ax.errorbar(
                x[~good],
                y[~good],
                yerr=yerr[:, ~good],
                fmt="o",
                ms=3.5,
                lw=0.6,
                mfc="none",
                color="0.5",
                alpha=0.7,
                label="classical flagged",
            )
        both = np.concatenate([x, y])
        lo_ax, hi_ax = float(np.nanmin(both)), float(np.nanmax(both))
        pad = 0.05 * (hi_ax - lo_ax or 1.0)
        ax.plot([lo_ax - pad, hi_ax + pad], [lo_ax - pad, hi_ax + pad], "k--", lw=0.8)
        ratio = float(np.median(y / x)) if np.all(x != 0) else math.nan
        summary.append((key, len(sel), ratio))
        ax.set_xlabel(f"classical {TARGET_LABELS[key]}")
        ax.set_ylabel(f"learned {TARGET_LABELS[key]}")
        ax.set_title(
            f"{TARGET_LABELS[key]}: learned (bars: {level or 'none'}) vs classical", fontsize=9
        )
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    text = "; ".join(
        f"{TARGET_LABELS[k]}: {n} traces, median learned/classical {r:.3g}" for k, n, r in summary
    )
    return (
        _img(_png_uri(fig), "learned against classical estimates")
        + f'<p class="caption">{_esc(text)}. Dashed: equality.</p>'
    )


# --------------------------------------------------------------------------- gallery


def _gallery_section(
    flagged: Sequence[_Row],
    table: ResultTable,
    overlays: Mapping[str, np.ndarray],
    max_gallery: int,
) -> str:
    shown = list(flagged[: max(max_gallery, 0)])
    left = flagged[len(shown) :]
    level = "95" if table.intervals or "U0_eV_lo95" in table.columns else None
    figs = []
    for r in shown:
        uri = _gallery_panel(r, overlays.get(r.trace.name), level)
        why = "; ".join(r.reasons())
        figs.append(
            f'<figure id="g{r.index}">{_img(uri, f"trace {r.name}")}'
            f"<figcaption><b>{_esc(r.name)}</b>: {_esc(why)}</figcaption></figure>"
        )
    n_over = sum(1 for r in shown if overlays.get(r.trace.name) is not None)
    head = (
        f'<p class="caption">{len(flagged)} flagged traces, {len(shown)} shown'
        + (f", {n_over} with the PT model at the estimate drawn over them" if n_over else "")
        + ". Titles give "
        + (f"the central {level} % interval" if level else "\u00b11 s.d. where known")
        + ".</p>"
    )
    tail = ""
    if left:
        names = ", ".join(r.name for r in left[:200])
        more = f" and {len(left) - 200} more" if len(left) > 200 else ""
        tail = (
            f'<p class="caption" id="gallery-left-out">{len(left)} more flagged traces '
            f"not shown: {_esc(names)}{_esc(more)}.</p>"
        )
    return head + f'<div class="gallery">{"".join(figs)}</div>' + tail


def _estimate_text(r: _Row, key: str, unit: str, level: str | None) -> tuple[str, str]:
    """``"U0 = 1.2 eV [1.0, 1.4]"`` and the kind of its bracket (``""`` if none)."""
    v = r.value(key)
    if not math.isfinite(v):
        return "", ""
    text = f"{'<F>' if key == 'F_mean_nN' else key.split('_')[0]} = {v:.3g}{unit}"
    if level:
        lo, hi = r.value(f"{key}_lo{level}"), r.value(f"{key}_hi{level}")
        if math.isfinite(lo) and math.isfinite(hi):
            return text + f" [{lo:.3g}, {hi:.3g}]", f"{level} % interval"
    s = r.value(f"{key}_std")
    if math.isfinite(s):
        return text + f" \u00b1 {s:.2g}", "\u00b11 s.d."
    return text, ""


def _gallery_panel(r: _Row, replicate: np.ndarray | None, level: str | None) -> str:
    fig = _figure(6.4, 3.2, (0.7, 0.15, 0.85, 0.5))
    ax = fig.subplots()
    x = np.asarray(r.trace.x_nm, float)
    f = np.asarray(r.trace.force_nN, float)
    ax.plot(x, f, "-", color="0.25", lw=0.7, label="trace")
    if replicate is not None:
        rep = np.asarray(replicate, float).ravel()
        xr = x if rep.size == x.size else np.linspace(x[0], x[-1], rep.size)
        ax.plot(xr, rep, "-", color="C1", lw=0.7, alpha=0.85, label="PT model at estimate")
        ax.legend(fontsize=7, loc="upper right")
    ests = [
        _estimate_text(r, "F_mean_nN", " nN", level),
        _estimate_text(r, "U0_eV", " eV", level),
        _estimate_text(r, "K_N_m", " N/m", level),
    ]
    ests = [e for e in ests if e[0]]
    lines = [textwrap.shorten(r.name, 90), textwrap.shorten("; ".join(r.reasons()), 100)]
    if ests:
        kinds = {k for _, k in ests}
        if len(kinds) == 1:  # one kind of bracket: say it once
            prefix = f"{kinds.pop() or 'estimates'}: "
            texts = [t for t, _ in ests]
        else:
            prefix = ""
            texts = [f"{t} ({k})" if k else t for t, k in ests]
        lines.append(prefix + texts[0])
        if texts[1:]:
            lines.append(", ".join(texts[1:]))
    fig.text(0.01, 0.985, "\n".join(lines), fontsize=8.5, ha="left", va="top")
    ax.set_xlabel("x (pixel)" if r.trace.meta.get("x_unit") == "px" else "x (nm)", fontsize=8)
    ax.set_ylabel(f"F ({r.trace.meta.get('unit') or 'nN'})", fontsize=8)
    ax.tick_params(labelsize=7.5)
    ax.grid(alpha=0.3)
    return _png_uri(fig, dpi=90)
