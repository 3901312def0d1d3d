"""What both ends of pibr must agree on: framing and messages (sans-I/O), poses and head
traces, the wide-angle projection, depth quantization, the link (latency) model and the
edge codec's bitstream. Imports nothing else of pibr."""
