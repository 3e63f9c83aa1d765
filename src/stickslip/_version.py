"""The installed package's version (one place, below every other module)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("stickslip")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"
