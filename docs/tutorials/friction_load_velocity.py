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
# # Friction against load and velocity
#
# Two classic experiments: friction measured at several normal loads (one map, the load
# lowered every few lines), and friction measured at several scan velocities (thermally
# activated stick-slip). You will simulate both, estimate U0 and K per load, fit the
# friction laws, and fit the thermal-activation law against velocity.

# %%
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
from gwyfile.objects import GwyContainer, GwyDataField, GwySIUnit
from IPython.display import Image

import stickslip

work = Path(tempfile.mkdtemp(prefix="stickslip-load-"))


def stickslip_cli(*args):
    """Run `stickslip ARGS...` (as in a terminal) and print the end of what it prints."""
    print("$ stickslip", " ".join(str(a) for a in args))
    run = subprocess.run([sys.executable, "-m", "stickslip.cli.main", *map(str, args)],
                         capture_output=True, text=True)
    print(run.stdout[-2000:], run.stderr[-1200:], sep="\n")
    assert run.returncode == 0, run.returncode


# %% [markdown]
# ## 1. A map with a load schedule
#
# As in the reference paper's experiments, one map whose load is lowered every 6 lines:
# 20, 15, 10 and 5 nN. In the PT model the load acts through the barrier: here U0 grows
# from 0.8 to 1.7 eV with load, K stays 10 N/m.

# %%
loads_nN = [20, 15, 10, 5]
U0_per_load = {20: 1.7, 15: 1.4, 10: 1.1, 5: 0.8}
lines_per_load = 6
U0 = np.repeat([U0_per_load[load] for load in loads_nN], lines_per_load)
n = U0.size
settings = stickslip.PhysicalSettings(length_nm=5.5, pixels=256)
sim = stickslip.simulate(np.concatenate([U0, U0]), np.full(2 * n, 10.0), settings, seed=3)
images = {"Friction Forward": sim.force_nN[:n], "Friction Backward": -sim.force_nN[n:, ::-1]}

calibration = 12.5  # nN/V
gwy = GwyContainer()
for i, (title, image_nN) in enumerate(images.items()):
    gwy[f"/{i}/data"] = GwyDataField(image_nN / calibration, xreal=5.5e-9, yreal=5.5e-9,
                                     si_unit_xy=GwySIUnit(unitstr="m"),
                                     si_unit_z=GwySIUnit(unitstr="V"))
    gwy[f"/{i}/data/title"] = title
map_file = work / "load_ramp.gwy"
gwy.tofile(str(map_file))

# %% [markdown]
# ## 2. U0 and K per load
#
# `--lines-per-load` and `--loads` give the schedule. Besides the table, `infer` writes
# `<out>.by_load.csv` and a plot of friction, U0 and K against load, and the per-map
# answer per load group (`<out>.groups.csv`).

# %%
schedule = ["--lines-per-load", lines_per_load, "--loads", ",".join(map(str, loads_nN))]
stickslip_cli("infer", map_file, "--calibration", calibration, *schedule,
              "--no-classical", "--out", work / "results.csv")
groups = pd.read_csv(work / "results.groups.csv")
groups[groups["direction"] == "both"][["load", "n_lines", "F_mean_nN", "U0_eV", "U0_eV_lo95",
                                       "U0_eV_hi95", "K_N_m"]].round(3)

# %% [markdown]
# ## 3. Friction against load
#
# `friction-load` fits two laws to the friction loops, a linear (Amontons-like)
# `F = mu L + F0` and a DMT-like `F = c (L + L_adh)^(2/3)`, and with `--estimates`
# adds the per-load pooled U0 and K from the table above.

# %%
stickslip_cli("friction-load", map_file, "--calibration", calibration, *schedule,
              "--out", work / "friction_load.png", "--fits", work / "fits.csv",
              "--estimates", work / "results.csv")
Image(filename=str(work / "friction_load.png"))

# %% [markdown]
# ## 4. Friction against velocity
#
# Thermal activation makes slips come early, the more so the slower the scan: the
# peak force grows with ln v up to a plateau. Simulate 16 short lines at each of five
# velocities (U0 = 1 eV, K = 3 N/m, eta = 17)...

# %%
velocities = [100, 300, 1000, 3000, 10000]
files = []
for i, v in enumerate(velocities):
    out = work / f"v{v}.h5"
    stickslip_cli("simulate", "--n", 16, "--u0-range", "1,1", "--k-range", "3,3",
                  "--velocity", v, "--length", 2, "--pixels", 96, "--seed", i + 1,
                  "--out", out)
    files.append(out)

# %% [markdown]
# ...and fit `F_peak(v) = F_c - (beta kB T ln(v_c / v))^(2/3)`. The command also
# checks the fit against the simulator at the lines' median U0 and K. The athermal
# peak force `F_c` should come out near `pi U0 / a = 2.05 nN`.

# %%
stickslip_cli("friction-velocity", *files, "--out", work / "fv.csv", "--plot", work / "fv.png")
Image(filename=str(work / "fv.png"))

# %% [markdown]
# Five velocities over two decades are few: the [validation page](../explanation/validation.md)
# and the [friction-velocity command](../reference/cli.md) say how many decades pin the
# attempt rate (three, reaching the knee where the friction levels off).
