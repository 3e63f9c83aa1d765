"""Write the docs' validation page from the benchmarks' JSON outputs.

    python scripts/validation_page.py [--data docs/validation] [--out PAGE.md]

Reads ``classical_stress.json`` (``benchmarks/classical_stress.py --json``),
``acquisition.json`` and ``acquisition_baseline.json`` (``benchmarks/acquisition.py
--json``),
``map_pooling.json`` (``benchmarks/map_pooling.py``'s ``last_run.json``),
``contacts.json`` (``benchmarks/contacts.py --json``),
``soft_contacts.json`` and ``soft_contacts_classical.json``
(``benchmarks/soft_contacts.py [--model classical] --json``) and
``transcribed.json`` (figures of benchmarks that write no JSON yet, each transcribed with
its command and date) from ``--data``; without ``--out`` the page goes to stdout. The
docs build (mkdocs-gen-files, ``scripts/docs_pages.py``) calls :func:`page`. To refresh
a figure, rerun its benchmark and copy its JSON output over the file in
``docs/validation/``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

DATA = Path(__file__).resolve().parents[1] / "docs" / "validation"


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def _stress(doc: dict) -> list[str]:
    date = doc["machine"]["date"][:10]
    quick = " --quick" if doc.get("quick") else ""
    shift = min(doc["seeds"].values()) - 3901  # the corpus's first draw starts at 3901
    quick += f" --seed-shift {shift}" if shift else ""
    cmd = f"`python benchmarks/classical_stress.py{quick} --json FILE`"
    head = (f"Measured {date} ({doc['machine']['cpu_count']} cores, "
            f"numba threads {doc['machine']['numba_threads']}, commit "
            f"{doc['machine']['git_head']}), {cmd}, seeds {min(doc['seeds'].values())}-"
            f"{max(doc['seeds'].values())} that no training or tuning uses.")
    lines = ["## Classical estimator: stress corpus", "", head, "",
             "| set | lines | answered | K rel. RMSE | K median / 95th pct | U0 rel. RMSE "
             "| command | date |", "|---|---|---|---|---|---|---|---|"]
    for name, s in doc["afm"].items():
        lines.append(f"| {name} | {s['n']} | {_pct(s['answered'])} | {_pct(s['K_rel_rmse'])} "
                     f"| {_pct(s['K_median'])} / {_pct(s['K_p95'])} | {_pct(s['U0_rel_rmse'])} "
                     f"| {cmd} | {date} |")
    sb = doc["spring_block"]["groups"]["all"]
    lines += ["", "Spring-block sliders (the macroscopic recordings' model), all regimes:", "",
              "| group | lines | answered | within 10 % of all | median error "
              "| answered and more than 20 % off | command | date |",
              "|---|---|---|---|---|---|---|---|",
              f"| slider sticks | {sb['sticks']['n']} | {_pct(sb['sticks']['answered'])} "
              f"| {_pct(sb['sticks']['within10_of_all'])} | {_pct(sb['sticks']['median_err'])} "
              f"| {sb['sticks']['off20']} | {cmd} | {date} |",
              f"| no sticking (refused is right) | {sb['oscillation']['n']} | "
              f"{_pct(sb['oscillation']['answered'])} (refused "
              f"{_pct(sb['oscillation']['refused'])}) | | | {sb['oscillation']['off20']} "
              f"| {cmd} | {date} |",
              f"| neither (grey) | {sb['grey']['n']} | {_pct(sb['grey']['answered'])} | | "
              f"| {sb['grey']['off20']} | {cmd} | {date} |", ""]
    return lines


def _pooling(doc: dict) -> list[str]:
    cfg = doc["config"]
    cmd = f"`NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 python {cfg['benchmark']} --write`"
    lines = ["## One answer per map: the calibrated floor", "",
             f"The systematic floor `sigma_sys` of the pooled interval, calibrated on "
             f"{cfg['calibration_maps']} simulated maps (seed {cfg['calibration_seed']}; "
             f"target: {cfg['target']}).", "",
             "| direction | <F> (relative; nN, in quadrature) | ln U0 (log units; nN over "
             "F_max, in quadrature) | ln K | ln eta | command | date |",
             "|---|---|---|---|---|---|---|"]
    floor_nN = doc.get("floor_nN", {})  # files before the absolute part have none
    offset_nN = doc.get("offset_nN", {})  # nor those before the log targets' offset part
    for key, label in (("single", "one direction"), ("both", "trace and retrace")):
        s, o = doc[key], offset_nN.get(key, {})
        F = f"{s['F_mean_nN']}" + (f"; {floor_nN[key]} nN" if key in floor_nN else "")
        logs = [f"{s[k]}" + (f"; {o[k]} nN" if k in o else "") for k in ("U0_eV", "K_N_m", "eta")]
        lines.append(f"| {label} | {F} | {' | '.join(logs)} | {cmd} | {cfg['date']} |")
    return [*lines, ""]


def _transcribed(doc: dict) -> list[str]:
    lines = ["## Other current figures", "", doc["about"], ""]
    section = None
    for f in doc["figures"]:
        if f["section"] != section:
            section = f["section"]
            lines += ["", f"### {section}", "", "| what | figure | command | date |",
                      "|---|---|---|---|"]
        lines.append(f"| {f['what']} | {f['figure']} | `{f['command']}` | {f['date']} |")
    return [*lines, ""]


def _acquisition(doc: dict, base: dict | None) -> list[str]:
    """The held-out acquisition sets (benchmarks/acquisition.py): the bundled model, and
    the model before the prior gained the dynamics and acquisition where recorded."""
    cmd = "`python benchmarks/acquisition.py --json FILE`"
    date = doc.get("date", "")
    lines = ["## The learned model: contact dynamics and acquisition (held-out sets)", "",
             f"Clean PT lines with white noise (0-0.05 nN), stated conditions right, one "
             f"factor varied per set (seeds 41001-41006, made before the training prior "
             f"changed and used by nothing else), {cmd}, {date}. Rows answered; U0 and K: "
             f"relative RMSE, median bias, 95 % coverage, sharpness (1: as wide as the "
             f"errors need); before: the model trained without these factors.", "",
             "| set | level | lines | U0 RMSE | U0 bias | U0 cov95 | U0 sharp | K RMSE "
             "| K bias | K cov95 | K sharp | ⟨F⟩ RMSE nN | ⟨F⟩ cov95 | before: U0 / K RMSE, "
             "cov95 |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, s in doc["sets"].items():
        for g, m in s["groups"].items():
            a = m["answered"]
            u, k, f = a["U0_eV"], a["K_N_m"], a["F_mean_nN"]
            before = ""
            if base and name in base["sets"] and g in base["sets"][name]["groups"]:
                b = base["sets"][name]["groups"][g]["answered"]
                before = (f"{_pct(b['U0_eV']['rel_rmse'])} / {_pct(b['K_N_m']['rel_rmse'])}, "
                          f"{b['U0_eV']['coverage95']:.2f} / {b['K_N_m']['coverage95']:.2f}")
            lines.append(
                f"| {name} | {g} | {m['lines']} | {_pct(u['rel_rmse'])} | "
                f"{100 * u['bias_median']:+.1f} % | {u['coverage95']:.3f} | "
                f"{u['sharpness_ratio']:.2f} | {_pct(k['rel_rmse'])} | "
                f"{100 * k['bias_median']:+.1f} % | {k['coverage95']:.3f} | "
                f"{k['sharpness_ratio']:.2f} | {f['rmse_nN']:.3f} | {f['coverage95']:.3f} | "
                f"{before} |")
    return [*lines, ""]


def _contacts(doc: dict) -> list[str]:
    """Multi-asperity contacts and tip changes (benchmarks/contacts.py --json)."""
    cmd, date = f"`{doc['command']} --json FILE`", doc["date"]
    lines = ["## Contacts that are not one point", "",
             f"Langevin lines at 296 K, 512 px over 11 nm, seeds {doc['seed']}-"
             f"{doc['seed'] + 1} (this benchmark's, scored once), {cmd}, {date}. Truth: the "
             "single PT that best reproduces the line's T = 0 waveform ([contacts]"
             "(contacts.md)). U0 and K on the rows in domain: relative RMSE, 95 % coverage, "
             "median relative 95 % half-width; for lines no PT describes and tip changes, "
             "the fraction out of domain or covered.", "",
             "| estimator | lines | n | in domain | U0 RMSE | U0 cov95 | U0 +- | K RMSE "
             "| K cov95 | K +- | out or covered (U0 / K) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]

    def cell(v: float | None, pct: bool = False) -> str:
        return "" if v is None else (_pct(v) if pct else f"{v:.3f}")

    for est, figs in doc["estimators"].items():
        for name, g in figs.items():
            if "in_domain" not in g:
                continue
            u, k = g["U0_eV"], g["K_N_m"]
            lines.append(
                f"| {est} | {name} | {g['n']} | {g['in_domain']:.3f} | "
                f"{cell(u['rel_rmse_in'], True)} | {cell(u['coverage95_in'])} | "
                f"{cell(u['halfwidth95_in'], True)} | {cell(k['rel_rmse_in'], True)} | "
                f"{cell(k['coverage95_in'])} | {cell(k['halfwidth95_in'], True)} | "
                f"{u['out_or_covered']:.3f} / {k['out_or_covered']:.3f} |")
        loc = figs.get("tip change located")
        if loc:
            lines.append(f"| {est} | tip change located | {loc['n']} | named on "
                         f"{loc['named']}, within 0.5 nm {cell(loc['within_0p5nm_of_named'])}"
                         " of those | | | | | | | |")
    return [*lines, ""]


def _soft(doc: dict, classical: dict | None) -> list[str]:
    """Soft contacts on coarse pixels (benchmarks/soft_contacts.py --json), beside the
    classical estimator on the same lines where recorded (``--model classical``)."""
    lines = ["## The learned model: soft contacts on coarse pixels", "",
             f"Clean PT lines with white noise (0-0.05 nN), U0 and K log-uniform, stated "
             f"conditions right, three pixel sizes (seed {doc['seed']}, used by nothing "
             f"else), `{doc['command']} --json FILE`; {doc['machine']}. Rows answered, by "
             f"true K" + (f"; classical: the classical estimator on the same lines, "
                          f"`{classical['command']}` (it gives no intervals)."
                          if classical else "."), "",
             "| pixels | K (N/m) | lines | K bias | K RMSE | K cov95 | U0 bias | U0 RMSE "
             "| U0 cov95 |" + (" classical: answered, K bias, K RMSE |" if classical else ""),
             "|---|---|---|---|---|---|---|---|---|" + ("---|" if classical else "")]
    for level, bins in doc["levels"].items():
        for name, g in bins.items():
            k, u = g["answered"]["K_N_m"], g["answered"]["U0_eV"]
            beside = ""
            if classical and name in classical["levels"].get(level, {}):
                c = classical["levels"][level][name]
                ck = c["answered"]["K_N_m"]
                beside = (f" {_pct((c['lines'] - c['refused']) / max(c['lines'], 1))}, "
                          f"{100 * ck['bias_median']:+.1f} %, {_pct(ck['rel_rmse'])} |")
            lines.append(
                f"| {level} | {name} | {g['lines']} | {100 * k['bias_median']:+.1f} % | "
                f"{_pct(k['rel_rmse'])} | {k['coverage95']:.3f} | "
                f"{100 * u['bias_median']:+.1f} % | {_pct(u['rel_rmse'])} | "
                f"{u['coverage95']:.3f} |{beside}")
    return [*lines, ""]


def page(data: Path = DATA) -> str:
    """The validation page (Markdown) from the JSON files in ``data``."""
    out = ["# Validation: current figures", "",
           "<!-- generated by scripts/validation_page.py from docs/validation/*.json; "
           "do not edit -->", "",
           "Every figure below carries the command that printed it and the date. The "
           "machine is this project's 2-core VM unless a row says otherwise. How the sets "
           "are built: [the learned model](learned-model.md), "
           "[the classical estimator](classical.md), [one answer per map](maps.md).", ""]
    out += _transcribed(json.loads((data / "transcribed.json").read_text()))
    out += _stress(json.loads((data / "classical_stress.json").read_text()))
    out += _pooling(json.loads((data / "map_pooling.json").read_text()))
    if (data / "contacts.json").exists():
        out += _contacts(json.loads((data / "contacts.json").read_text()))
    if (data / "acquisition.json").exists():
        base = data / "acquisition_baseline.json"
        out += _acquisition(json.loads((data / "acquisition.json").read_text()),
                            json.loads(base.read_text()) if base.exists() else None)
    if (data / "soft_contacts.json").exists():
        other = data / "soft_contacts_classical.json"
        out += _soft(json.loads((data / "soft_contacts.json").read_text()),
                     json.loads(other.read_text()) if other.exists() else None)
    return "\n".join(out).replace("<F>", "⟨F⟩") + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    text = page(args.data)
    if args.out:
        args.out.write_text(text)
    else:
        print(text, end="")


if __name__ == "__main__":
    main()
