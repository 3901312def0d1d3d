"""Helpers the server, the client and the benchmarks share that are no contract between them:

- :mod:`.gl`: OpenGL contexts, created in one place, each owned by one thread;
- :mod:`.traces`: head traces by name or file, their formats, synthetic traces, placement in a scene;
- :mod:`.link`: the network link model (delay, jitter, bandwidth cap) and a session's schedule through it;
- :mod:`.replay`: the display ticks of a trace window and the server frame each one shows;
- :mod:`.quality`: quality levels chosen against a deadline (the client's ticks, the server's frames);
- :mod:`.tls`: optional TLS for the TCP connections (contexts, certificate pins, connecting);
- :mod:`.address` and :mod:`.arguments`: the command lines' text forms and argparse types.
- :mod:`.child_setup`: what a ``python -m pibr`` child sets itself at start-up (Ctrl-C, its CPUs).

Imports only :mod:`pibr.protocol` (DESIGN.md, Layout).
"""
