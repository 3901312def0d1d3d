"""pibr.scenes."""
