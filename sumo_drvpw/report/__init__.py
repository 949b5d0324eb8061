"""Reports and figures: comparison report (report.json, report.md) and its figures."""
