"""Reports and figures: the comparison report (``comparison``: report.json, report.md) and its
figures (``figures``), the tracer's report (``diagnose``: trace.json, trace.md; ``chain_trace``
for chain targets), and number formatting (``format``)."""
