"""estimators/window."""
