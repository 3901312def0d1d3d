"""The LoD generator's numba kernels give the bits the numpy code gave: winding numbers, closest
points and voxel hulls against the reference (``lod_reference.py``), whole proxies against the
reference run and against fingerprints pinned from main before the kernels (``golden_lod.py``)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from pibr.scenes import lod, mesh_queries, voxelize
from pibr.scenes import primitives as prim
from pibr.scenes.registry import load_scene

from . import golden_lod
from . import lod_reference as ref


@pytest.fixture(scope="module")
def room():
    return load_scene("room")


def _sphere_with_slivers():
    """A tessellated unit sphere plus a collinear, a collapsed and an edge-like triangle."""
    mesh = prim.sphere(1.0, 24, 12)
    v, f = mesh.vertices.astype(np.float64), mesh.faces.astype(np.int64)
    n = len(v)
    v = np.vstack([v, [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [0.5, 0.0, 0.0]]])
    f = np.vstack([f, [[n, n + 1, n + 2], [n + 3, n + 3, n + 3], [n, n, n + 1]]])
    return v, f


def _query_points(v):
    rng = np.random.default_rng(7)
    return {
        "random": rng.uniform(-1.6, 1.6, (2000, 3)),
        "on vertices": v[rng.integers(0, len(v), 300)],                  # on the surface: ties
        "on a lattice": np.round(rng.uniform(-2.0, 2.0, (1500, 3)), 1),    # exact zeros in the sums
        "edge midpoints": 0.5 * (v[rng.integers(0, len(v), 300)] + v[rng.integers(0, len(v), 300)]),
    }


def test_winding_numbers_are_bit_identical_to_the_numpy_reference():
    v, f = _sphere_with_slivers()
    for name, pts in _query_points(v).items():
        for faces in (f, f[:-3]):
            got, want = mesh_queries.winding_numbers(pts, v, faces), ref.winding_numbers(pts, v, faces)
            assert got.tobytes() == want.tobytes(), name
    # chunking (rows per chunk) does not change a row's value
    pts = _query_points(v)["random"]
    assert (mesh_queries.winding_numbers(pts, v, f, chunk_pairs=50_000).tobytes()
            == ref.winding_numbers(pts, v, f, chunk_pairs=50_000).tobytes())
    assert mesh_queries.winding_numbers(np.zeros((0, 3)), v, f).shape == (0,)
    assert mesh_queries.winding_numbers(pts, v, f[:0]).tobytes() == np.zeros(len(pts)).tobytes()


@pytest.mark.parametrize("facing_slack", [None, 0.0, 0.05])
def test_closest_points_are_bit_identical_to_the_numpy_reference(facing_slack):
    v, f = _sphere_with_slivers()
    for name, pts in _query_points(v).items():
        got = mesh_queries.closest_points_on_mesh(pts, v, f, facing_slack=facing_slack)
        want = ref.closest_points_on_mesh(pts, v, f, facing_slack=facing_slack)
        for g, w in zip(got, want):
            assert g.dtype == w.dtype and g.shape == w.shape
            assert g.tobytes() == w.tobytes(), name
    empty = mesh_queries.closest_points_on_mesh(np.zeros((0, 3)), v, f)
    assert [a.shape for a in empty] == [(0,), (0, 3), (0,)]


def test_room_queries_are_bit_identical(room):
    """Real proxies and real vertex sets: the queries encaging makes on the torus knot."""
    knot = next(o for o in room.objects if o.name == "exhibit_torus_knot").mesh
    pts = np.unique(knot.vertices.astype(np.float64), axis=0)
    proxy = lod.simplify_encaging(knot, resolution=32).proxy
    pv, pf = proxy.vertices.astype(np.float64), proxy.faces.astype(np.int64)
    pv = pv * 0.97                                                   # shrink it: many points outside
    assert (mesh_queries.winding_numbers(pts, pv, pf).tobytes() == ref.winding_numbers(pts, pv, pf).tobytes())
    for slack in (None, 1e-3):
        got = mesh_queries.closest_points_on_mesh(pts, pv, pf, facing_slack=slack)
        want = ref.closest_points_on_mesh(pts, pv, pf, facing_slack=slack)
        assert all(g.tobytes() == w.tobytes() for g, w in zip(got, want))


@pytest.mark.parametrize("name", ["exhibit_torus_knot", "tree_leaves", "books", "distant_hills", "lamp_1_cable"])
def test_voxel_hulls_are_identical_to_the_scipy_reference(room, name):
    mesh = next(o for o in room.objects if o.name == name).mesh
    faces = mesh.faces.astype(np.int64)
    lo, hi = mesh.vertices[np.unique(faces)].astype(np.float64).min(0), mesh.vertices.max(0).astype(np.float64)
    for res in (128, 37, 16):
        voxel = float(np.max(hi - lo)) / res
        grid_lo = lo - lod.PADDING_VOXELS * voxel
        dims = np.floor((hi - lo) / voxel).astype(np.int64) + 1 + 2 * lod.PADDING_VOXELS
        got = voxelize.voxel_hull(mesh.vertices, faces, grid_lo, voxel, dims)
        want = ref.voxel_hull(mesh.vertices, faces, grid_lo, voxel, dims)
        assert got.shape == want.shape and np.array_equal(got, want), res
    # an open tube: the flood fill enters it, so the hull is a hollow shell
    tube = prim.cylinder(0.3, 1.0, 48, caps=False, height_segments=24)
    lo, hi = tube.vertices.min(0).astype(np.float64), tube.vertices.max(0).astype(np.float64)
    voxel = float(np.max(hi - lo)) / 40
    dims = np.floor((hi - lo) / voxel).astype(np.int64) + 1 + 2 * lod.PADDING_VOXELS
    args = (tube.vertices, tube.faces.astype(np.int64), lo - lod.PADDING_VOXELS * voxel, voxel, dims)
    assert np.array_equal(voxelize.voxel_hull(*args), ref.voxel_hull(*args))


@pytest.mark.parametrize("name", ["exhibit_torus_knot", "distant_hills", "books", "railing_balusters"])
def test_proxies_are_identical_to_the_reference_run(room, monkeypatch, name):
    """The whole generator with the kernels and with the numpy / scipy reference swapped in."""
    mesh = next(o for o in room.objects if o.name == name).mesh
    new = lod.simplify_encaging(mesh, resolution=48)
    monkeypatch.setattr(lod, "winding_numbers", ref.winding_numbers)
    monkeypatch.setattr(lod, "closest_points_on_mesh", ref.closest_points_on_mesh)
    monkeypatch.setattr(lod, "voxel_hull", ref.voxel_hull)
    old = lod.simplify_encaging(mesh, resolution=48)
    assert new.iterations > 0                                       # encaging ran: the queries mattered
    assert golden_lod.fingerprint(new) == golden_lod.fingerprint(old)
    assert new.proxy.vertices.tobytes() == old.proxy.vertices.tobytes()
    assert new.proxy.faces.tobytes() == old.proxy.faces.tobytes()


def test_proxies_match_the_fingerprints_pinned_before_the_kernels():
    golden = json.loads(golden_lod.GOLDEN_PATH.read_text())
    if golden["libraries"] != golden_lod.library_versions():
        pytest.skip(f"pinned with {golden['libraries']}, running {golden_lod.library_versions()}: "
                    "marching cubes, decimation and numpy's SIMD loops may round differently")
    got = golden_lod.generate()["objects"]
    assert sorted(got) == sorted(golden["objects"])
    changed = [name for name in got if got[name] != golden["objects"][name]]
    assert not changed, f"proxies changed: {changed}"
