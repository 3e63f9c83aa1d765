"""Physical constants and the simulator's internal unit system.

Public APIs take SI-flavoured, unit-suffixed arguments (``U0_eV``, ``K_N_m``,
``velocity_nm_per_s``, ``mass_kg``, ``dt_s``...). Inside the integrators everything is
expressed in **nm, ns, nN**: then stiffness is in nN/nm = N/m, energy in nN nm = 1e-18 J,
and mass in nN ns^2/nm = 1e-18 kg. All quantities are of order one there, which keeps
float64 arithmetic well conditioned and the kernels free of unit factors.
"""

from __future__ import annotations

KB_J_PER_K = 1.380649e-23  # Boltzmann constant, J/K (exact, SI 2019)
EV_J = 1.602176634e-19  # electron volt, J (exact)

EV_TO_NN_NM = EV_J * 1e18  # 1 eV in nN nm
KB_NN_NM_PER_K = KB_J_PER_K * 1e18  # Boltzmann constant in nN nm / K
KG_TO_INTERNAL_MASS = 1e18  # 1 kg in nN ns^2 / nm
PER_S_TO_PER_NS = 1e-9
S_TO_NS = 1e9


def eta_from(U0_eV, K_N_m, lattice_nm):
    """PT parameter ``eta = 2 pi^2 U0 / (K a^2)`` (dimensionless; array-friendly)."""
    import numpy as np

    return 2.0 * np.pi**2 * (np.asarray(U0_eV) * EV_TO_NN_NM) / (
        np.asarray(K_N_m) * np.asarray(lattice_nm) ** 2
    )


def fmax_nN(U0_eV, lattice_nm):
    """Maximum lateral force of the sinusoidal potential, ``F_max = pi U0 / a`` in nN."""
    import numpy as np

    return np.pi * np.asarray(U0_eV) * EV_TO_NN_NM / np.asarray(lattice_nm)
