"""Where golden payloads live and how their generator modules write them (``python -m
tests.protocol.golden_NAME`` regenerates one family; review the diff before committing)."""
from __future__ import annotations

import os

GOLDEN_DIR = os.path.join(os.path.dirname(__file__), "golden")


def write_goldens(names, make) -> None:
    """Write ``make(name)`` (bytes) to ``GOLDEN_DIR/name.bin`` for every name."""
    os.makedirs(GOLDEN_DIR, exist_ok=True)
    for name in names:
        data = make(name)
        with open(os.path.join(GOLDEN_DIR, f"{name}.bin"), "wb") as f:
            f.write(data)
        print("wrote", name, len(data), "bytes")
