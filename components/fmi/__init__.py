"""pythonfmu wrappers: one slave class per block, thin over the FMI-free logic."""
