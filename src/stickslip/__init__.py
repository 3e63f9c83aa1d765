"""stickslip: Prandtl-Tomlinson parameters from atomic-scale stick-slip friction traces.

Subpackages follow the pipeline:

- :mod:`stickslip.simulators` -- finite-temperature PT simulator and datasets,
- :mod:`stickslip.traces` -- trace formats and I/O,
- :mod:`stickslip.estimators.classical` -- classical (slip-detection) estimator,
- :mod:`stickslip.learning` -- features, networks, training and inference,
- :mod:`stickslip.evaluation` -- metrics, plots and reports,
- :mod:`stickslip.cli` -- the ``stickslip`` command.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("stickslip")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
