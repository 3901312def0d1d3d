"""Worker of ``pibr bench codec-speed``: one pibr checkout's edge codec, timed stage by stage.

Run as a script (``python codec_speed_worker.py FRAMES.npz [--root CHECKOUT]``) so that the
baseline and the current code each live in a process of their own and import their own
``pibr`` (``--root``: a pibr source tree, e.g. a ``git worktree`` of ``main``; default: the
installed pibr). The driver (:mod:`pibr.bench.codec_speed`) sends one JSON line per frame
index on stdin; the worker answers one JSON line with process CPU ms per stage, bytes, a
digest of the payload and of the decoded samples, and disparity PSNR after reconstruction.

Stages are timed with ``time.process_time`` (CPU time of this process, less disturbed by
other processes than wall time). Besides the top-level stages the worker wraps, by name,
whichever of the codec's and the diffusion's inner functions the checkout has, so the same
worker breaks down old and new code alike; those timings are inclusive (a wrapped function
calling another wrapped one counts both).

This file imports nothing of pibr at module level: it must run against any checkout.
"""
from __future__ import annotations

import argparse
import hashlib
import importlib
import inspect
import json
import math
import os
import sys
import tempfile
import time

import numpy as np

#: Top-level stages, in pipeline order.
STAGES = ("enc.warp", "enc.extract", "enc.encode", "dec.warp", "dec.decode", "dec.diffuse")
#: (module, function names) wrapped for the breakdown when the checkout has them.
INNER = {
    "pibr.protocol.edgecodec.codec": ("quantize_codes", "laplacian", "select_edges", "encode_edge_image",
                                      "encode_regular", "encode_values", "decode_edge_image", "decode_regular",
                                      "decode_values", "temporal_context", "temporal_values", "_assemble"),
    "pibr.server.edge_extract": ("quantize_codes", "significance", "select_edges"),
    "pibr.client.diffusion": ("_label_regions", "_label_runs", "_diffuse_regions", "push_pull_fast",
                              "codes_to_distance"),
}


def use_checkout(root: str) -> None:
    """Make ``import pibr`` load the source tree ``root`` (folders cli/, protocol/, ... as in setup.py)."""
    shim = tempfile.mkdtemp(prefix="pibr-checkout-")
    pkg = os.path.join(shim, "pibr")
    os.mkdir(pkg)
    for name in os.listdir(os.path.join(root, "cli")):
        os.symlink(os.path.join(root, "cli", name), os.path.join(pkg, name))
    for sub in ("protocol", "common", "scenes", "server", "client", "bench"):
        if os.path.isdir(os.path.join(root, sub)):   # common/: since the checkout split it off protocol/
            os.symlink(os.path.join(root, sub), os.path.join(pkg, sub))
    sys.path.insert(0, shim)
    for name in [m for m in sys.modules if m == "pibr" or m.startswith("pibr.")]:
        del sys.modules[name]


class StageClock:
    """Accumulates process CPU ms per stage name."""

    def __init__(self):
        self.ms: dict[str, float] = {}

    def add(self, name: str, seconds: float) -> None:
        self.ms[name] = self.ms.get(name, 0.0) + seconds * 1e3

    def wrap(self, module, name: str) -> None:
        fn = getattr(module, name)
        clock = self

        def timed(*args, **kwargs):
            t0 = time.process_time()
            try:
                return fn(*args, **kwargs)
            finally:
                clock.add(f"{module.__name__.rsplit('.', 1)[-1]}.{name}", time.process_time() - t0)

        setattr(module, name, timed)


def disparity_psnr(r_true: np.ndarray, r_test: np.ndarray, near: float) -> float:
    """PSNR (peak 1) of disparity near / r (sky = 0) over all pixels, as ``pibr bench codec`` reports it."""
    d_true = np.where(r_true > 0, near / np.maximum(r_true, near), 0.0)
    d_test = np.where(r_test > 0, near / np.maximum(r_test, near), 0.0)
    mse = float(np.mean((d_true - d_test) ** 2))
    return 100.0 if mse == 0 else min(100.0, 10 * math.log10(1.0 / mse))


def digest(*arrays) -> str:
    h = hashlib.sha1()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("frames")
    ap.add_argument("--root", default=None)
    args = ap.parse_args(argv)
    if args.root:
        use_checkout(os.path.abspath(args.root))
    import pibr.client.diffusion as diffusion
    import pibr.protocol.edgecodec.codec as codec
    from pibr.protocol.pose import Pose
    from pibr.server import edge_extract
    try:   # where the edge codec's quantizer lives: protocol/depth_codecs.py since the codec registry
        from pibr.protocol.depth_codecs import EDGE_BITS, edge_quantizer
    except ImportError:
        from pibr.server.depth_stream import EDGE_BITS, edge_quantizer

    data = np.load(args.frames)
    distances, positions, orientations = data["distance"], data["position"], data["orientation"]
    starts = data["window_start"]
    near, far = float(data["near"]), float(data["far"])
    n, h, w = distances.shape
    quantizer = edge_quantizer(near, far, EDGE_BITS)
    encoder = codec.EdgeEncoder(w, h, EDGE_BITS, quantizer)
    decoder = codec.EdgeDecoder(w, h, EDGE_BITS, quantizer)
    passes_codes = "codes" in inspect.signature(encoder.encode).parameters
    # a persistent workspace where the checkout has one, as its client's depth stream keeps
    workspace = diffusion.DiffusionWorkspace() if hasattr(diffusion, "DiffusionWorkspace") else None
    clock = StageClock()
    for mod_name, names in INNER.items():
        module = importlib.import_module(mod_name)
        for name in names:
            if hasattr(module, name):
                clock.wrap(module, name)
    state = {"enc": None, "dec": None}

    def run(i: int) -> dict:
        if starts[i]:
            state["enc"] = state["dec"] = None
        clock.ms = {}
        r_true = distances[i]
        pose = Pose.make(positions[i], orientations[i])
        pt = time.process_time
        t0 = pt()
        warped = codec.warp_samples(*state["enc"], pose, quantizer) if state["enc"] else None
        t1 = pt()
        found = edge_extract.extract_edge_samples(r_true, quantizer)
        t2 = pt()
        extra = {"codes": found.codes} if passes_codes else {}
        enc = encoder.encode(r_true, None if warped is None else warped.edges,
                             None if warped is None else warped.values, edges=found.edges, signs=found.signs, **extra)
        t3 = pt()
        warped_d = codec.warp_samples(*state["dec"], pose, quantizer) if state["dec"] else None
        t4 = pt()
        samples = decoder.decode(enc.payload, None if warped_d is None else warped_d.edges,
                                 None if warped_d is None else warped_d.values)
        t5 = pt()
        dense = diffusion.diffuse(samples) if workspace is None else diffusion.diffuse(samples, workspace=workspace)
        t6 = pt()
        inner = dict(clock.ms)
        clock.ms = {}
        plain = diffusion.diffuse_plain(samples)
        t7 = pt()
        state["enc"], state["dec"] = (enc.samples, pose), (samples, pose)
        stats = enc.stats
        ms = dict(zip(STAGES, np.diff([t0, t1, t2, t3, t4, t5, t6]) * 1e3))
        ms["dec.diffuse_plain"] = (t7 - t6) * 1e3
        return {"frame": i, "ms": {k: float(v) for k, v in ms.items()}, "inner_ms": inner,
                "bytes": stats.total_bytes, "edge_bytes": stats.edge_bytes, "value_bytes": stats.value_bytes,
                "regular_bytes": stats.regular_bytes, "n_edges": stats.n_edges,
                "payload_digest": hashlib.sha1(enc.payload).hexdigest()[:16],
                "samples_digest": digest(samples.edges, samples.signs, samples.codes, samples.valid),
                "encoder_view_matches": bool(np.array_equal(samples.codes, enc.samples.codes)
                                             and np.array_equal(samples.valid, enc.samples.valid)),
                "psnr_db": disparity_psnr(r_true, diffusion.codes_to_distance(dense, quantizer), near),
                "plain_psnr_db": disparity_psnr(r_true, diffusion.codes_to_distance(plain, quantizer), near)}

    run(0)  # compile / load the numba kernels before anything is timed
    print(json.dumps({"ready": True, "pibr": os.path.dirname(codec.__file__)}), flush=True)
    for line in sys.stdin:
        msg = json.loads(line)
        if msg.get("quit"):
            break
        print(json.dumps(run(int(msg["frame"]))), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
