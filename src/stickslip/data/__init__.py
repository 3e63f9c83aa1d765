"""Trace formats and I/O: the reader layer every command reads through, and datasets."""

from stickslip.data.trace import (
    Trace,
    TraceReadError,
    collect_traces,
    read_trace_csv,
    write_trace_csv,
)

__all__ = ["Trace", "TraceReadError", "collect_traces", "read_trace_csv", "write_trace_csv"]
