"""Pages of the docs site generated from the code at build time (mkdocs-gen-files).

- ``reference/cli.md``: every command of the Typer app with its arguments and options;
- ``reference/columns.md``: the result table's columns, from the code's own lists
  (``stickslip.estimators.table.COLUMNS`` and the estimators' column lists); the build
  fails on a column without a description here, so the page cannot drift;
- ``explanation/validation.md``: ``scripts/validation_page.py``.

``python scripts/docs_pages.py DIR`` writes the same pages under DIR (to look at them).
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import typer

sys.path.insert(0, str(Path(__file__).resolve().parent))
import validation_page  # noqa: E402

TARGET_TEXT = {
    "F_mean_nN": "mean friction ⟨F⟩ over the line, nN",
    "U0_eV": "barrier U0 (peak to peak), eV",
    "K_N_m": "effective contact stiffness K, N/m",
    "eta": "eta = 2 pi^2 U0 / (K a^2), dimensionless",
    "F_mean_V": "⟨F⟩ of a trace in volts (no calibration), V",
    "U0_V_nm": "U0 of a trace in volts, as F_max a / pi, V nm",
    "K_V_per_nm": "K of a trace in volts, V/nm",
}
SUFFIX_TEXT = {
    "std": "standard deviation (the estimator's spread; classical: over slips)",
    "lo68": "lower end of the central 68 % interval", "hi68": "upper end of the 68 % interval",
    "lo95": "lower end of the central 95 % interval", "hi95": "upper end of the 95 % interval",
    "tau": "between-line standard deviation (ln scale for U0, K, eta; nN for ⟨F⟩)",
    "tau_lo95": "lower end of tau's 95 % interval", "tau_hi95": "upper end of tau's 95 % interval",
}
DESCRIPTIONS = {
    "trace": "the trace's name: the file stem for a one-trace file, the line's full name "
             "(`file:channel:direction:Lnnn`) for map lines",
    "estimator": "the estimator's name",
    "quality": "`ok`, or why there is no estimate (read error, refusal, classical flag)",
    "lattice_nm": "lattice spacing a used, nm", "lattice_source": "`flag`, `file` or `model`",
    "velocity_nm_per_s": "scan velocity used, nm/s",
    "velocity_source": "`flag`, `file` or `model`",
    "temperature_K": "temperature used, K", "temperature_source": "`flag`, `file` or `model`",
    "file": "the input file", "channel": "the file's channel (maps)",
    "direction": "`trace` or `retrace` (maps); in the per-map table also `both`",
    "line": "scan line number (maps)", "load": "normal load or setpoint of the line's group",
    "load_unit": "unit of `load`",
    # classical estimator (classical.estimator.CLASSICAL_COLUMNS; also as classical_*)
    "regime": "`single slip`, `multiple slip`, `stick-slip`, `smooth` or `not stick-slip`",
    "k_exp_N_m": "median fitted stick slope, N/m",
    "k_exp_N_m_std": "spread of the stick slopes over slips, N/m",
    "F_peak_nN": "mean peak force before a slip, corrected for thermal activation, nN",
    "F_peak_nN_std": "spread of the peak forces over slips, nN",
    "n_slips": "number of slips found", "noise_nN": "the line's noise level, nN",
    # trace/retrace pairs (estimators.pairs.PAIR_COLUMNS)
    "friction_pair_nN": "mean of the two directions' ⟨F⟩ (cancels offsets that do not "
                        "reverse with the scan), nN",
    "offset_pair_nN": "the pair's lateral offset (half the difference of the rows' ⟨F⟩ "
                      "with signs as recorded), nN",
    "pair_trace": "the other row of the pair",
    "U0_pair_eV": "geometric mean of the two rows' U0, eV",
    "K_pair_N_m": "geometric mean of the two rows' K, N/m",
    "eta_pair": "geometric mean of the two rows' eta",
}
#: columns some estimators add that no code list names (estimators/domain.py, window,
#: line model, --check, readers, maps)
OTHER_COLUMNS = {
    "in_domain": "the in/out-of-domain verdict (true/false)",
    "domain_score": "at most 1 in domain",
    "change_nm": "where the line changes part-way (nm): the verdict found two regimes, "
                 "e.g. a tip change (--split-changes estimates each part)",
    "domain_reason": "why a row is out of domain (see the how-to on the reasons)",
    "stick_slip_check": "the classical refusal that put a low-eta row out of domain",
    "F_model_std_nN": "the line model's own ⟨F⟩ spread, without offsets, nN",
    "evidence_slow": "line model: what the line shows of slow, non-periodic content (drift, "
                     "a defect, a step): ln of the RMS left once the lattice-periodic profile "
                     "is taken off and the rest averaged over a period, over the profile's "
                     "std; dimensionless",
    "evidence_spikes": "line model: what the line shows of spikes: ln of its largest second "
                       "difference over their robust scale (MAD); dimensionless",
    "evidence_local": "line model: what the line shows of a local anomaly (a defect): ln of "
                      "the largest response of its slow residual to a filter a few lattice "
                      "periods wide that answers to a localised bump and not to an offset, "
                      "a slope or a curvature, over the profile's std; dimensionless",
    "map_reason": "why a map line was left out of its map's pooled answer (inconsistent "
                  "with its map, or showing what its other lines do not)",
    "n_windows": "window MLP: number of windows", "F_mean_net": "window MLP: the network's ⟨F⟩",
    "gof": "`--check`: RMS z-score of the posterior predictive check (about 1 or below: fits)",
    "ppc_flag": "`--check`: 1 where gof > 3", "masked_pixels": "NaN pixels interpolated",
    "classical_*": "the classical estimator's columns beside a learned model's "
                   "(`--classical`, the default of `infer`)",
}
GROUP_TEXT = {
    "group": "the group's name", "load_group": "load group index (`--lines-per-load`)",
    "segment": "`all`, or `before`/`after` a change point", "lines": "the lines pooled",
    "n_lines": "number of lines in the group",
    "n_left_out": "lines without an estimate, out of domain, or flagged",
    "change_line": "first line after a change along the slow scan axis",
    "flagged_lines": "lines left out as inconsistent with the map or unlike its other "
                     "lines (see `map_reason`)", "note": "a remark",
}


def describe(name: str) -> str:
    """The description of a column name, from the tables above (KeyError if none)."""
    for table in (DESCRIPTIONS, GROUP_TEXT, TARGET_TEXT):
        if name in table:
            return table[name]
    for base in sorted({**TARGET_TEXT, "friction_pair_nN": 0, "U0_pair_eV": 0,
                        "K_pair_N_m": 0, "eta_pair": 0, "k_exp_N_m": 0, "F_peak_nN": 0},
                       key=len, reverse=True):
        if name.startswith(base + "_") and name[len(base) + 1:] in SUFFIX_TEXT:
            return f"{SUFFIX_TEXT[name[len(base) + 1:]]} of `{base}`"
    raise KeyError(f"column {name!r} has no description in scripts/docs_pages.py")


def _table(names) -> list[str]:
    return ["| column | meaning |", "|---|---|",
            *(f"| `{n}` | {describe(n)} |" for n in names)]


def columns_page() -> str:
    """The result table's columns, generated from the code's lists."""
    from stickslip.estimators.classical.estimator import CLASSICAL_COLUMNS
    from stickslip.estimators.pairs import PAIR_COLUMNS
    from stickslip.estimators.pooling import GROUP_COLUMNS
    from stickslip.estimators.table import COLUMNS

    out = ["# The result table's columns", "",
           "<!-- generated by scripts/docs_pages.py from the code's column lists -->", "",
           "Every estimator returns the same table, one row per trace and one per unreadable "
           "input (`ResultTable`; `table.to_frame()` in Python, `--out` as `.csv`, `.json` "
           "or `.parquet`). A missing value is an empty cell in CSV and `null` in JSON.", "",
           "## Standard columns", "",
           "In this order where present (`stickslip.estimators.table.COLUMNS`):", "",
           *_table(COLUMNS), "",
           "## Classical estimator", "",
           "`stickslip.estimators.classical.estimator.CLASSICAL_COLUMNS`; beside a learned "
           "model's estimate the same with the prefix `classical_`.", "",
           *_table(CLASSICAL_COLUMNS), "",
           "## Trace/retrace pairs", "",
           "Where a map gives both scan directions of a line "
           "(`stickslip.estimators.pairs.PAIR_COLUMNS`):", "", *_table(PAIR_COLUMNS), "",
           "## Other columns", "", "Added by some estimators and options:", "",
           "| column | meaning |", "|---|---|",
           *(f"| `{k}` | {v} |" for k, v in OTHER_COLUMNS.items()), "",
           "## The per-map table (`<out>.groups.csv`, `table.groups()`)", "",
           "`stickslip.estimators.pooling.GROUP_COLUMNS`; see "
           "[one answer per map](../explanation/maps.md).", "", *_table(GROUP_COLUMNS), ""]
    return "\n".join(out)


def _escape(text: str) -> str:
    return re.sub(r"<(?=[A-Za-z/])", "&lt;", text.replace("|", "\\|")).replace("\n", " ")


def cli_page() -> str:
    """Every command of the ``stickslip`` Typer app, with its parameters."""
    from stickslip.cli.main import app

    group = typer.main.get_command(app)
    globals_ = ", ".join(f"`{'`, `'.join(p.opts)}` ({_escape(p.help or '')})"
                         for p in group.params if p.param_type_name == "option")
    out = ["# Command line", "", "<!-- generated by scripts/docs_pages.py from the Typer app "
           "(stickslip.cli.main.app) -->", "",
           f"Every command prints `--help`. Options before the command: {globals_}.", ""]
    for name in sorted(group.commands):
        cmd = group.commands[name]
        args = [p for p in cmd.params if p.param_type_name == "argument"]
        usage = " ".join(f"{p.name.upper()}{'...' if p.nargs == -1 else ''}" for p in args)
        out += [f"## `stickslip {name}`", "", (cmd.help or "").strip(), "",
                "```text", f"stickslip {name} [OPTIONS] {usage}".rstrip(), "```", "",
                "| argument / option | default | meaning |", "|---|---|---|"]
        for p in cmd.params:
            if p.param_type_name == "option":
                opts = ", ".join(f"`{o}`" for o in (*p.opts, *p.secondary_opts))
            else:
                opts = f"`{p.name.upper()}`"
            default = "" if p.required or p.default in (None, (), False) else f"`{p.default}`"
            req = " (required)" if p.required else ""
            out.append(f"| {opts}{req} | {_escape(default)} | {_escape(p.help or '')} |")
        out.append("")
    return "\n".join(out)


PAGES = {"reference/cli.md": cli_page, "reference/columns.md": columns_page,
         "explanation/validation.md": validation_page.page}


def write_all(write) -> None:
    """Call ``write(path, text)`` for every generated page."""
    for path, make in PAGES.items():
        write(path, make())


def _gen_files() -> None:
    import mkdocs_gen_files

    def write(path: str, text: str) -> None:
        with mkdocs_gen_files.open(path, "w") as f:
            f.write(text)

    write_all(write)


if __name__ == "__main__" and len(sys.argv) == 2:
    root = Path(sys.argv[1])

    def _write(path: str, text: str) -> None:
        (root / path).parent.mkdir(parents=True, exist_ok=True)
        (root / path).write_text(text)

    write_all(_write)
else:
    _gen_files()
