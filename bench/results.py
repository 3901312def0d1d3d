"""Where benchmark results go: one JSON file per result, in the run's output folder."""
from __future__ import annotations

import json
import os


def write_result(out_dir: str, name: str, result: dict) -> str:
    """Write ``result`` as indented JSON to ``out_dir/name`` (creating the folder); -> the path."""
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, name)
    with open(path, "w") as f:
        json.dump(result, f, indent=2)
    return path
