"""estimators/line."""
