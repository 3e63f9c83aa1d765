# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Your first friction map
#
# You will simulate a small friction map, save it as a Gwyddion `.gwy` file in volts
# (as a microscope would), read it back, estimate the Prandtl-Tomlinson parameters of
# every scan line, write an HTML report, and read the answer off the table.
#
# Needs `pip install 'stickslip[formats]'` (for `gwyfile`). The first call compiles
# the simulator's kernels once (numba); later runs reuse them.

# %%
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from gwyfile.objects import GwyContainer, GwyDataField, GwySIUnit

import stickslip

work = Path(tempfile.mkdtemp(prefix="stickslip-tutorial-"))


def stickslip_cli(*args):
    """Run `stickslip ARGS...` (as in a terminal) and print what it prints."""
    print("$ stickslip", " ".join(str(a) for a in args))
    run = subprocess.run([sys.executable, "-m", "stickslip.cli.main", *map(str, args)],
                         capture_output=True, text=True)
    print(run.stdout[-3000:], run.stderr[-1500:], sep="\n")
    assert run.returncode == 0, run.returncode

# %% [markdown]
# ## 1. Simulate a map
#
# A real map has many lines at one contact. Here: 8 lines of 5.5 nm and 256 pixels,
# all with U0 = 1.5 eV and K = 10 N/m (eta = 7.8, multiple slip possible), at the
# paper preset's 296 K and 60 nm/s on graphite (a = 0.246 nm). The forward (trace) and
# backward (retrace) scans are separate simulations.

# %%
U0_eV, K_N_m, n_lines = 1.5, 10.0, 8
settings = stickslip.PhysicalSettings(length_nm=5.5, pixels=256)
sim = stickslip.simulate(np.full(2 * n_lines, U0_eV), np.full(2 * n_lines, K_N_m), settings,
                         seed=1)
forward = sim.force_nN[:n_lines]
# A retrace is stored as the microscope records it: in increasing x, with the force of
# backward sliding (negative). The readers reverse and sign-flip it again.
backward = -sim.force_nN[n_lines:, ::-1]
print(forward.shape, f"eta = {sim.eta[0]:.2f}, mean friction {forward.mean():.3f} nN")

# %% [markdown]
# ## 2. Write it as a vendor file, in volts
#
# The photodiode gives volts; a lateral calibration (here 12.5 nN/V) turns them into
# force. We store volts, as the instrument would, and give the calibration when
# reading.

# %%
calibration_nN_per_V = 12.5
gwy = GwyContainer()
for i, (title, image_nN) in enumerate([("Friction Forward", forward),
                                       ("Friction Backward", backward)]):
    gwy[f"/{i}/data"] = GwyDataField(
        image_nN / calibration_nN_per_V, xreal=5.5e-9, yreal=5.5e-9,
        si_unit_xy=GwySIUnit(unitstr="m"), si_unit_z=GwySIUnit(unitstr="V"))
    gwy[f"/{i}/data/title"] = title
map_file = work / "my_map.gwy"
gwy.tofile(str(map_file))

# %% [markdown]
# ## 3. Look inside the file
#
# `stickslip inspect` lists the channels, the scan size and the traces it would
# extract.

# %%
stickslip_cli("inspect", map_file)

# %% [markdown]
# ## 4. Estimate: the command line
#
# One command reads the map, runs the bundled whole-line model (with the classical
# estimator beside it), writes the table and a self-contained HTML report.

# %%
stickslip_cli("infer", map_file, "--calibration", calibration_nN_per_V,
              "--out", work / "results.csv", "--report", work / "report.html")
print(sorted(p.name for p in work.iterdir()))

# %% [markdown]
# ## 5. The same from Python, and reading off the answer
#
# `read_traces` gives one trace per scan line and direction; `predict` returns the
# result table (`.to_frame()` is a pandas DataFrame; the columns are listed in the
# [result table reference](../reference/columns.md)).

# %%
traces, errors = stickslip.read_traces([map_file], calibration_nN_per_V=calibration_nN_per_V)
table = stickslip.predict(traces)
df = table.to_frame()
df[["trace", "direction", "U0_eV", "U0_eV_lo95", "U0_eV_hi95", "K_N_m", "eta",
    "in_domain"]].round(3)

# %% [markdown]
# Every line has its own estimate and 95 % interval. The map as a whole gets one
# answer per scan direction and for both together (`table.groups()`, written as
# `results.groups.csv` by the command), pooled over the lines with a floor for the
# errors every line of a map shares ([one answer per map](../explanation/maps.md)):

# %%
groups = table.groups()
groups[["direction", "n_lines", "U0_eV", "U0_eV_lo95", "U0_eV_hi95", "K_N_m", "K_N_m_lo95",
        "K_N_m_hi95"]].round(3)

# %% [markdown]
# The truth was U0 = 1.5 eV and K = 10 N/m. The pooled interval is wider than the
# lines' scatter: it carries the errors every line of one map shares (the lateral
# calibration, the stated conditions, the tip), which no number of lines averages
# away. The `both` row (trace and retrace together) is the one to quote: it cancels
# offsets that do not reverse with the scan.

# %%
both = groups[groups["direction"] == "both"].iloc[0]
print(f"U0 = {both['U0_eV']:.2f} eV (95 %: {both['U0_eV_lo95']:.2f}-{both['U0_eV_hi95']:.2f}), "
      f"K = {both['K_N_m']:.1f} N/m (95 %: {both['K_N_m_lo95']:.1f}-{both['K_N_m_hi95']:.1f})")
