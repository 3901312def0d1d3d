"""The edge codec for depth (and motion): Pajak et al. 2011, "Scalable remote rendering with depth
and motion-flow augmented streaming".

Depth survives streaming as a lossless binary *edge image* (where the Laplacian of the quantized
disparity is significant, two pixels wide), the *values* of those edge samples (predicted from
already coded samples on the same surface, optionally quantized), and one *regular sample* per
32 x 32 cell; the client diffuses them back into a dense map (``pibr.client.diffusion``).

Modules: :mod:`.arith` (context-adaptive binary arithmetic coder, pure Python and numba),
:mod:`.bitstream` (frame format and its limits), :mod:`.edges` (edge image: four interleaved
passes or raster, temporal context), :mod:`.values` (edge values), :mod:`.regular` (regular
samples), :mod:`.motion` (motion of moving objects: mask and block means), :mod:`.flow` (motion as
edge samples, Pajak et al.'s way; both coders serve ``protocol/motion_flow.py``), :mod:`.codec` (the API).

Both ends must run the same version of this package: the bitstream is pinned by golden
payloads in ``tests/protocol/golden/edge_*.bin``. The numba kernels are cached on disk
(``cache=True``); numba does not notice when a kernel's callee in another module changes,
so after editing :mod:`.arith` delete this package's ``__pycache__/*.nbi`` files.
"""
from .codec import (DecodedSamples, EdgeDecoder, EdgeEncoder, EncodedDepth, EncodeStats, WarpedPrevious,
                    default_quantizer, laplacian, select_edges, warp_samples)

__all__ = ["DecodedSamples", "EdgeDecoder", "EdgeEncoder", "EncodedDepth", "EncodeStats", "WarpedPrevious",
           "default_quantizer", "laplacian", "select_edges", "warp_samples"]
