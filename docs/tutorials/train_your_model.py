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
# # Train a model for your instrument
#
# The bundled models were trained on graphite-like conditions (a = 0.246 nm,
# 60 nm/s, 296 K) and map other lattices onto them. If your instrument works under
# other conditions, you can simulate training data under exactly those conditions,
# train a model on it, score it on a held-out set, and compare it with the bundled
# models, all with four commands.
#
# This tutorial keeps everything tiny (a few hundred short lines, a few epochs) so that
# it runs in well under a minute; the numbers it prints show the workflow, not the
# accuracy a full training reaches. For real use, scale `--n` to thousands and drop
# `--epochs` (see the [command reference](../reference/cli.md)).

# %%
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

work = Path(tempfile.mkdtemp(prefix="stickslip-train-"))


def stickslip_cli(*args):
    """Run `stickslip ARGS...` (as in a terminal) and print the end of what it prints."""
    print("$ stickslip", " ".join(str(a) for a in args))
    run = subprocess.run([sys.executable, "-m", "stickslip.cli.main", *map(str, args)],
                         capture_output=True, text=True)
    print(run.stdout[-1500:], run.stderr[-800:], sep="\n")
    assert run.returncode == 0, run.returncode
    return run


# %% [markdown]
# ## 1. Simulate under your conditions
#
# Say your instrument scans MoS2 (a = 0.316 nm) at 60 nm/s and room temperature, and
# your contacts span U0 0.5-3 eV and K 5-30 N/m. A training sweep and a held-out test
# sweep with another seed (5.5 nm lines of 256 pixels: the paper's pixel size).

# %%
conditions = ["--lattice", 0.316, "--velocity", 60, "--temperature", 296,
              "--u0-range", "0.5,3", "--k-range", "5,30", "--length", 5.5, "--pixels", 256]
stickslip_cli("simulate", "--n", 240, "--seed", 11, *conditions, "--out", work / "train.h5")
stickslip_cli("simulate", "--n", 80, "--seed", 12, *conditions, "--out", work / "test.h5")

# %% [markdown]
# ## 2. Train
#
# The reference paper's physics-informed window MLP (`--kind window --features pi`)
# trains in seconds; the whole-line kind (`--kind line`, the default) is the more
# robust estimator but needs far more data and time.

# %%
stickslip_cli("train", "--kind", "window", "--features", "pi", "--data", work / "train.h5",
              "--epochs", 15, "--seed", 0, "--out", work / "my_mlp.pt")

# %% [markdown]
# ## 3. Evaluate, and compare with the bundled models
#
# `evaluate` scores any estimator on a sweep (whose truths are stored in it): your
# model, the bundled window MLP (`window`) and the bundled whole-line model (the
# default); `--model classical` scores the classical estimator the same way.

# %%
models = {"my_mlp.pt": work / "my_mlp.pt", "bundled window MLP": "window",
          "bundled line model": None}
rows = []
for name, model in models.items():
    out = work / f"eval_{name.replace(' ', '_')}"
    args = ["evaluate", "--data", work / "test.h5", "--out", out]
    if model is not None:
        args += ["--model", model]
    stickslip_cli(*args)
    metrics = json.loads((out / "metrics.json").read_text())
    rows.append({"model": name, **{f"{t} rel. RMSE": metrics[t]["rel_rmse"]
                                   for t in ("U0_eV", "K_N_m", "eta")},
                 "answered": metrics["U0_eV"]["answered"]})
pd.DataFrame(rows).round(3)

# %% [markdown]
# Each evaluation folder also holds `metrics.csv`, `predictions.csv` (every row with
# its truth), `parity.png`, and, for estimators with intervals, `reliability.png` (how
# often the 68 % and 95 % intervals hold the truth).
#
# With this little data your model will usually trail the bundled ones; with a few
# thousand trajectories under your own conditions it need not. Whatever you train,
# the comparison above is how to decide. Use the model with
# `stickslip infer my_files/ --model my_mlp.pt --out results.csv`.
