"""pibr.client."""
