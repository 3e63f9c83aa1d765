"""Trace formats and I/O: the reader layer every command reads through, and datasets."""

from stickslip.traces.readers import collect_traces, read_trace_csv
from stickslip.traces.trace import (
    Trace,
    TraceReadError,
    write_trace_csv,
)

__all__ = ["Trace", "TraceReadError", "collect_traces", "read_trace_csv", "write_trace_csv"]
