"""Drive logs in: the canonical drive log, measured power, the one loader, vendor adapters."""
