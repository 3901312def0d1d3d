"""pibr.bench."""
