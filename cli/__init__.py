"""pibr: hide network latency in remote rendering with proxy-guided image-based rendering."""
__version__ = "0.1.0"
