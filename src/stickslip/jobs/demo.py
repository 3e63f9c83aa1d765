"""The ``demo`` job: the bundled model on the bundled example traces."""

from __future__ import annotations

import json
from importlib.resources import as_file, files
from pathlib import Path

from stickslip.traces.formats.text import read_text
from stickslip.traces.trace import Trace

EXAMPLES = "examples"
MANIFEST = "manifest.json"


def examples_dir():
    """The bundled example traces (a Traversable inside the installed package)."""
    return files("stickslip").joinpath("resources", EXAMPLES)


def load_examples() -> tuple[list[Trace], dict[str, dict]]:
    """Bundled example traces (with lattice/velocity in ``meta``) and their true values."""
    root = examples_dir()
    manifest = json.loads(root.joinpath(MANIFEST).read_text())
    traces, truth = [], {}
    for item in manifest:
        with as_file(root.joinpath(item["file"])) as p:
            (t,) = read_text(Path(p))
        t.name = Path(item["file"]).stem
        t.meta.update({k: item[k] for k in ("lattice_nm", "velocity_nm_per_s") if k in item})
        traces.append(t)
        truth[t.name] = item
    return traces, truth
