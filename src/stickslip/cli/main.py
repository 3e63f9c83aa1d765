"""Entry point: the app with every command module's commands (imported for that)."""

from __future__ import annotations

from stickslip.cli import formats, learn, simulate, velocity
from stickslip.cli.app import app

COMMAND_MODULES = (formats, learn, simulate, velocity)  # each adds its commands to `app`


def main() -> None:
    """Console-script entry point."""
    app()


if __name__ == "__main__":
    main()
