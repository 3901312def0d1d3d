"""pibr.server."""
