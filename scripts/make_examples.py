"""Simulate the bundled example traces used by ``stickslip demo``.

Writes a few simulated lines (clean and with white detector noise, several U0/K/eta,
one on MoS2 at 30 nm/s) as trace CSVs into src/stickslip/resources/examples/, with a
manifest.json holding each trace's true parameters, lattice and velocity.

Usage: python scripts/make_examples.py [--seed 2024]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from stickslip.atomic import write_text_atomic
from stickslip.simulators import PRESETS, simulate
from stickslip.traces.trace import write_trace_csv
from stickslip.units import eta_from

OUT = Path(__file__).resolve().parents[1] / "src" / "stickslip" / "resources" / "examples"

# name, U0 [eV], K [N/m], preset, white-noise sigma [nN]
EXAMPLES = [
    ("graphene_clean_single_slip", 1.0, 12.0, "paper", 0.0),
    ("graphene_clean_stiff", 4.0, 40.0, "paper", 0.0),
    ("graphene_clean_multiple_slip", 3.0, 6.0, "paper", 0.0),
    ("graphene_noisy_0.05nN", 2.0, 15.0, "paper", 0.05),
    ("graphene_noisy_0.1nN", 1.5, 8.0, "paper", 0.1),
    ("mos2_a0.316_v30", 2.5, 20.0, "mos2", 0.0),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=2024)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    manifest = []
    for i, (name, U0, K, preset, noise) in enumerate(EXAMPLES):
        ph = PRESETS[preset]
        res = simulate([U0], [K], ph, seed=args.seed, indices=[i])
        force = res.force_nN[0] + noise * rng.standard_normal(res.force_nN.shape[1])
        write_trace_csv(OUT / f"{name}.csv", res.x_nm, force)
        manifest.append({
            "file": f"{name}.csv", "U0_eV": U0, "K_N_m": K,
            "eta": float(eta_from(U0, K, ph.lattice_nm)),
            "F_mean_nN": float(res.force_nN[0].mean()), "noise_nN": noise,
            "lattice_nm": ph.lattice_nm, "velocity_nm_per_s": ph.velocity_nm_per_s,
            "temperature_K": ph.temperature_K,
        })  # fmt: skip
        print(f"{name}: eta {manifest[-1]['eta']:.2f}")
    write_text_atomic(OUT / "manifest.json", json.dumps(manifest, indent=2) + "\n")


if __name__ == "__main__":
    main()
