"""What both ends of pibr must agree on, and nothing else: framing and messages with the
session's parameters (sans-I/O), poses and the head-trace type, the wide-angle projection,
depth quantization, the proxy bundle and the edge codec's bitstream. Imports nothing else of
pibr; helpers both ends share that are no contract live in :mod:`pibr.common`."""
