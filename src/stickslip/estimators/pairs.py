"""Trace/retrace pairs: the friction of a scan line from both directions.

A friction map gives each scan line twice, as a trace and a retrace
(:mod:`stickslip.traces.formats.maps`). The readers store the retrace reversed in x
and sign-flipped, so that both rows read as friction in their own scan direction. With
``F`` the friction (it reverses with the scan direction) and ``o`` an additive offset
of the lateral signal that does not (detector offset, topography crosstalk), the raw
signals are ``+F + o`` forward and ``-F + o`` backward; after the reader's sign flip
the two rows carry

    trace:   F_mean = <F> + <o>          retrace: F_mean = <F> - <o>

so that

    friction_pair_nN = (F_trace + F_retrace) / 2     (the offset cancels)
    offset_pair_nN   = (F_trace - F_retrace) / 2     (the offset, friction cancels)

where ``F_trace``, ``F_retrace`` are the two rows' ``F_mean_nN`` estimates. This is the
friction loop's ``(trace - retrace) / 2`` of the raw images, with each row's estimate in
place of the raw mean. Both rows keep their own ``F_mean_nN`` and get the pair's
columns.

Uncertainty. Where the rows carry ``F_model_std_nN`` (the line model's <F> error
without the offset term its single-row interval holds, :mod:`stickslip.estimators.
offsets`), the pair's std is the mean of the two and its intervals are Gaussian about
the pair's value: the offset cancels in the pair, so its interval is the model's alone.
Otherwise the pair's ``friction_pair_nN_std`` and its 68 / 95 % intervals are the
means of the two rows' (``(std_t + std_r) / 2``, ``(lo_t + lo_r) / 2``, ...): the
interval of the mean of two fully correlated errors. Independent errors would give
intervals ~1/sqrt(2) as wide; but the rows share the line, the substrate, the model and
its systematic errors, so independence would claim a precision the pair does not have.
Where the rows' errors are dominated by the offset, which enters them with opposite
signs, the pair is better than this bound says; it is never worse for Gaussian errors.

The PT parameters of the pair. A learned model reads U0, K and eta partly off the
force's level, so an offset moves them too, up in one direction and down in the other
(``docs/explanation/``, "Offsets restated in every calibration"). The pair's
``U0_pair_eV``, ``K_pair_N_m`` and ``eta_pair`` are the geometric means of the two
rows' estimates (the mean of their logarithms), where the offset's first-order effect
cancels. Their intervals combine the rows' log half-widths as for independent errors,
``sqrt(h_t^2 + h_r^2) / 2`` per side: the rows' intervals carry the offset's effect,
which cancels in the pair, so the fully correlated bound of the friction is too wide
here (on ``benchmarks/families.py``'s pairs of pool 601 it covered 0.984-0.995; this
rule 0.924-0.948, and 0.919-0.948 on pools 602 and 603). The std is the log-normal's
with the pair's 68 % interval, as the line model gives it.

The offset along the line. An estimator that reads the PT parameters off the force's
levels (the classical inversion takes F_max from the peaks) is thrown by an offset of
the force's zero, which one line cannot tell from friction: a tilt or a curvature of
the sample adds one, and crosstalk too. The pair can: over one lattice period both
directions' stick-slip has the same mean (the friction), so the running mean over one
period of their half-difference, both in the same x order, is the offset that does not
reverse with the scan, ``o(x)`` (:func:`shared_offset`), slope and curvature included.
:func:`offset_free_pairs` gives both rows of every pair less it (the retrace row, stored
reversed and sign-flipped, plus it, reversed), as the classical estimator reads them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Hashable, Mapping, MutableMapping, Sequence
from typing import Any

import numpy as np

from stickslip.estimators.calibration import Z68, Z95, lognormal_std
from stickslip.estimators.periodic import period_means
from stickslip.estimators.table import BOUNDS, is_missing
from stickslip.traces.formats.common import RETRACE, TRACE
from stickslip.traces.trace import Trace

FRICTION = "F_mean_nN"
PAIR = "friction_pair_nN"
OFFSET = "offset_pair_nN"

#: Rows of traces in volts (no calibration) carry their friction as ``F_mean_V``: their
#: pair's columns are ``friction_pair_V ...``, ``offset_pair_V``.
UNITS = {"F_mean_nN": "nN", "F_mean_V": "V"}
#: the std of a row's <F> error without the offset and compression terms (line model
#: with those priors, :mod:`stickslip.estimators.offsets`)
MODEL_STD = "F_model_std_nN"
#: The pair's PT parameters: each row's column and the pair's (module docstring).
PARAMETER_PAIRS = {"U0_eV": "U0_pair_eV", "K_N_m": "K_pair_N_m", "eta": "eta_pair"}
#: The columns a pair puts on both of its rows (in nN; volts rows: ``*_V``).
PAIR_COLUMNS = (PAIR, f"{PAIR}_std", *(f"{PAIR}_{b}" for b in BOUNDS), OFFSET, "pair_trace",
                *(f"{p}{s}" for p in PARAMETER_PAIRS.values()
                  for s in ("", "_std", *(f"_{b}" for b in BOUNDS))))  # fmt: skip


def pair_key(trace: Trace) -> tuple[Hashable, ...] | None:
    """The scan line a trace belongs to, ``(source, channel, load, line)``, or None for a
    trace that is not one direction of a map line."""
    meta = trace.meta or {}
    if meta.get("direction") not in (TRACE, RETRACE) or is_missing(meta.get("line")):
        return None
    return (trace.source, meta.get("channel"), meta.get("load"), meta.get("line"))


def find_pairs(traces: Sequence[Trace | None]) -> list[tuple[int, int]]:
    """Index pairs ``(trace, retrace)`` of the same scan line, in input order.

    A line with one direction only, or with a direction given more than once (the same
    file read twice), is not paired: which two rows belong together would be a guess.
    """
    slots: dict[tuple[Hashable, ...], dict[str, list[int]]] = {}
    for i, t in enumerate(traces):
        key = None if t is None else pair_key(t)
        if key is not None:
            slots.setdefault(key, {TRACE: [], RETRACE: []})[t.meta["direction"]].append(i)
    return sorted((s[TRACE][0], s[RETRACE][0]) for s in slots.values()
                  if len(s[TRACE]) == 1 and len(s[RETRACE]) == 1)  # fmt: skip


def _value(row: Mapping[str, Any], key: str) -> float:
    v = row.get(key)
    if isinstance(v, (int, float, np.integer, np.floating)) and not is_missing(v):
        return float(v)
    return float("nan")


def pair_friction(trace_row: Mapping[str, Any], retrace_row: Mapping[str, Any]
                  ) -> dict[str, float]:  # fmt: skip
    """The pair's columns from the two rows (see the module docstring); empty when either
    row has no friction estimate (or the two are in different units). Intervals only
    where both rows have them."""
    both = [k for k in UNITS if np.isfinite(_value(trace_row, k))
            and np.isfinite(_value(retrace_row, k))]  # fmt: skip
    if not both:
        return {}
    friction, unit = both[0], UNITS[both[0]]
    ft, fr = _value(trace_row, friction), _value(retrace_row, friction)
    pair, offset = f"friction_pair_{unit}", f"offset_pair_{unit}"
    out = {pair: 0.5 * (ft + fr), offset: 0.5 * (ft - fr)}
    mt, mr = _value(trace_row, MODEL_STD), _value(retrace_row, MODEL_STD)
    if unit == "nN" and np.isfinite(mt) and np.isfinite(mr):
        # the rows' <F> intervals carry the offset prior; the pair cancels the offset.
        # A compression does not cancel, but the members read friction through it, and
        # the pair's model interval is measured to hold (benchmarks/families.py)
        sd = 0.5 * (mt + mr)
        out[f"{pair}_std"] = sd
        for b, z in zip(BOUNDS, (-Z68, Z68, -Z95, Z95), strict=True):
            out[f"{pair}_{b}"] = out[pair] + z * sd
        return out
    for suffix in ("std", *BOUNDS):
        key = f"{friction}_{suffix}"
        vt, vr = _value(trace_row, key), _value(retrace_row, key)
        if np.isfinite(vt) and np.isfinite(vr):
            out[f"{pair}_{suffix}"] = 0.5 * (vt + vr)
    return out


def pair_parameters(trace_row: Mapping[str, Any], retrace_row: Mapping[str, Any]
                    ) -> dict[str, float]:  # fmt: skip
    """The pair's ``U0_pair_eV``, ``K_pair_N_m`` and ``eta_pair`` (see the module
    docstring), each where both rows have a positive estimate, with intervals where
    both rows have all four bounds."""
    out: dict[str, float] = {}
    for key, name in PARAMETER_PAIRS.items():
        vt, vr = _value(trace_row, key), _value(retrace_row, key)
        if not (vt > 0.0 and vr > 0.0):  # also False for NaN
            continue
        m = 0.5 * (np.log(vt) + np.log(vr))
        out[name] = float(np.exp(m))
        bounds = {b: (_value(trace_row, f"{key}_{b}"), _value(retrace_row, f"{key}_{b}"))
                  for b in BOUNDS}  # fmt: skip
        if not all(t > 0.0 and r > 0.0 for t, r in bounds.values()):
            continue
        for b, (bt, br) in bounds.items():
            # each row's log half-width on this side, combined as independent errors
            ht, hr = abs(np.log(bt) - np.log(vt)), abs(np.log(br) - np.log(vr))
            sign = -1.0 if b.startswith("lo") else 1.0
            out[f"{name}_{b}"] = float(np.exp(m + sign * 0.5 * np.hypot(ht, hr)))
        e = (np.log(out[f"{name}_hi68"]) - np.log(out[f"{name}_lo68"])) / (2.0 * Z68)
        out[f"{name}_std"] = float(lognormal_std(np.exp(m), e))
    return out


def add_pair_columns(rows: Sequence[MutableMapping[str, Any]],
                     traces: Sequence[Trace | None]) -> int:  # fmt: skip
    """Put the pair's columns on both rows of every trace/retrace pair; returns the
    number of pairs. ``rows[i]`` is the row of ``traces[i]`` (None: no trace)."""
    n = 0
    for it, ir in find_pairs(traces[: len(rows)]):
        cols = pair_friction(rows[it], rows[ir])
        if not cols:
            continue
        cols.update(pair_parameters(rows[it], rows[ir]))
        for i, other in ((it, ir), (ir, it)):
            rows[i].update(cols)
            rows[i]["pair_trace"] = rows[other].get("trace")
        n += 1
    return n


def shared_offset(trace_row: np.ndarray, retrace_row: np.ndarray,
                  period_samples: float) -> np.ndarray:  # fmt: skip
    """The offset the two directions of a scan line share, along the trace row.

    Parameters
    ----------
    trace_row, retrace_row : ndarray (n,)
        The two rows as the readers store them (the retrace reversed in x and
        sign-flipped, so that it reads as friction in its own scan direction).
    period_samples : float
        Samples per lattice period.

    Returns
    -------
    ndarray (n,)
        ``o(x)``: the mean over exactly one period (fractional ends weighted,
        :func:`~stickslip.estimators.periodic.period_means`) of ``(trace(x) -
        retrace(x)) / 2`` with both in the trace's x order, where the friction
        cancels; within half a period of the ends, where no whole period is centred,
        carried on straight from the first (last) period and a half. The mean of the
        half-difference where the line is shorter than one and a half periods.
    """
    t = np.asarray(trace_row, float)
    r = np.asarray(retrace_row, float)[::-1]
    h = 0.5 * (t - r)  # (F_t - F_r) / 2 + o: the friction's period means cancel
    n = h.size
    P = float(period_samples)
    if not (P > 0) or 1.5 * P >= n:
        return np.full(n, float(np.mean(h)) if n else 0.0)
    # the mean over [c - P/2, c + P/2] of sample centres c; those within P/2 of an end
    # take the straight line through the means centred at P/2 and P from that end

    def mean_at(c: np.ndarray) -> np.ndarray:
        return period_means(h, P, np.asarray(c, float) - P / 2)

    c = np.arange(n) + 0.5
    o = mean_at(np.clip(c, P / 2, n - P / 2))
    for edge, inward in ((P / 2, 1.0), (n - P / 2, -1.0)):
        m0, m1 = mean_at(np.array([edge, edge + inward * P / 2]))
        out = (c - edge) * inward < 0
        o[out] = m0 + (c[out] - edge) * (m1 - m0) / (inward * P / 2)
    return o


def offset_free_pairs(traces: Sequence[Trace], lattice_nm: Sequence[float]
                      ) -> tuple[list[Trace], int]:  # fmt: skip
    """Every trace/retrace pair (:func:`find_pairs`) less the offset it shares.

    Parameters
    ----------
    traces : sequence of Trace
    lattice_nm : sequence of float
        The lattice each trace is read at (one per trace).

    Returns
    -------
    traces : list of Trace
        The traces, the paired ones replaced by copies less :func:`shared_offset` (the
        retrace row plus it, reversed); others unchanged. A pair whose rows differ in
        length or sampling is left as it is.
    n : int
        The number of pairs taken the offset off.
    """
    out = list(traces)
    n = 0
    for it, ir in find_pairs(out):
        t, r = out[it], out[ir]
        xt, xr = np.asarray(t.x_nm, float), np.asarray(r.x_nm, float)
        if xt.size != xr.size or xt.size < 3 or not np.allclose(np.diff(xt), np.diff(xr)):
            continue
        dx = abs(float(xt[-1] - xt[0])) / (xt.size - 1)
        if not dx > 0:
            continue
        o = shared_offset(t.force_nN, r.force_nN, float(lattice_nm[it]) / dx)
        out[it] = dataclasses.replace(t, force_nN=np.asarray(t.force_nN, float) - o)
        out[ir] = dataclasses.replace(r, force_nN=np.asarray(r.force_nN, float) + o[::-1])
        n += 1
    return out, n
