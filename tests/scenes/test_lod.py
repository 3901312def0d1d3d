"""Encaging LoD proxies (pibr.scenes.lod), their disk cache and the LoD benchmark."""
from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np
import pytest

from pibr.protocol.errors import SceneError
from pibr.scenes import lod
from pibr.scenes import lod_cache
from pibr.scenes import primitives as prim
from pibr.scenes.lod import (LodResult, closest_points_on_mesh, is_closed, is_watertight, make_manifold,
                             measure_enclosure, signed_volume, simplify_encaging, winding_numbers)
from pibr.scenes.registry import load_scene
from pibr.scenes.scene import Mesh

SPOT = Path(__file__).resolve().parents[2] / "scenes" / "data" / "assets" / "spot_triangulated.obj"
#: Fast resolution for whole-scene tests (the default is 128; one object is checked there too).
FAST_RES = 48


def assert_valid(result: LodResult, mesh: Mesh) -> None:
    """What every LoD result must satisfy: encaging, watertight, counts and kinds consistent."""
    assert result.kind in LodResult.KINDS
    assert result.triangles_original == mesh.triangle_count
    assert result.triangles_proxy == result.proxy.triangle_count
    if result.kind == "empty":
        assert result.proxy.triangle_count == 0
        return
    # Encaging is a guarantee, not a tendency: the simplified proxy is only kept when every
    # original vertex is inside or within tolerance; otherwise the proxy is the (enclosing) box.
    assert result.enclosed_fraction == 1.0, result.note
    assert result.max_outside_distance <= result.params["tolerance"] + 1e-12
    assert is_watertight(result.proxy.faces)
    assert is_watertight(result.box.faces) and result.box.triangle_count == 12
    if result.kind == "box":
        np.testing.assert_array_equal(result.proxy.vertices, result.box.vertices)
    else:
        target = result.params["target_triangles"]
        # decimation retries nudge the target by up to 21 % to avoid pinched edges
        assert result.triangles_proxy <= math.ceil(1.35 * target)
        assert result.triangles_proxy >= 4
        assert signed_volume(result.proxy.vertices, result.proxy.faces) < \
            signed_volume(result.box.vertices, result.box.faces)


@pytest.fixture(scope="module")
def room():
    return load_scene("room")


@pytest.fixture
def cache_dir(tmp_path, monkeypatch) -> Path:
    d = tmp_path / "lodcache"
    monkeypatch.setenv(lod_cache.ENV_VAR, str(d))
    return d


# ----------------------------------------------------------------------------- geometry helpers

def test_winding_numbers_and_closest_points_against_brute_force():
    trimesh = pytest.importorskip("trimesh")
    rng = np.random.default_rng(3)
    mesh = prim.sphere(1.0, 24, 12)
    v, f = mesh.vertices.astype(np.float64), mesh.faces.astype(np.int64)
    pts = rng.uniform(-1.6, 1.6, (300, 3))
    r = np.linalg.norm(pts, axis=1)
    w = winding_numbers(pts, v, f)
    # the tessellated sphere lies between radius cos(pi / 12) * 1 and 1
    assert np.all(np.abs(w[r < 0.95] - 1.0) < 1e-9) and np.all(np.abs(w[r > 1.01]) < 1e-9)
    d, q, t = closest_points_on_mesh(pts, v, f)
    tri = v[f]
    brute = np.array([np.linalg.norm(trimesh.triangles.closest_point(tri, np.repeat(p[None], len(tri), 0)) - p,
                                     axis=1).min() for p in pts])
    np.testing.assert_allclose(d, brute, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(q - pts, axis=1), d, atol=1e-12)
    # degenerate (collinear) triangle: its edges still count
    d, q, _ = closest_points_on_mesh(np.array([[1.5, 1.0, 0.0]]), np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]),
                                     np.array([[0, 1, 2]]))
    assert d[0] == pytest.approx(1.0) and np.allclose(q[0], [1.5, 0, 0])


def test_make_manifold_splits_pinched_edges_without_moving_anything():
    # two tetrahedra glued along one edge: closed (every edge matched) but not 2-manifold
    a = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    b = a * [1, -1, -1] + [0, 0, 0]
    v = np.vstack([a, b[2:]])                      # share vertices 0 and 1 (the edge)
    tet = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    t2 = np.array([[0, 4, 1], [0, 1, 5], [0, 5, 4], [1, 4, 5]])[:, ::-1]   # mirrored: keep outward
    f = np.vstack([tet, t2])
    assert is_closed(f) and not is_watertight(f)
    nv, nf = make_manifold(v, f)
    assert is_watertight(nf) and len(nv) > len(v)
    pts = np.random.default_rng(0).uniform(-1, 1, (200, 3))
    np.testing.assert_allclose(winding_numbers(pts, nv, nf), winding_numbers(pts, v, f), atol=1e-12)
    assert not is_watertight(f[1:])                # an open mesh is not


# ----------------------------------------------------------------------------- the room

def test_every_room_object_is_encaged(room, cache_dir):
    results = lod_cache.lods_for_scene(room, resolution=FAST_RES, target_fraction=0.005, progress=False)
    assert list(results) == [o.name for o in room.objects]
    for obj in room.objects:
        assert_valid(results[obj.name], obj.mesh)
    kinds = {name: r.kind for name, r in results.items()}
    # the dense meshes beat their boxes; meshes under 2 400 triangles get 12 at 0.5 %: the box
    assert kinds["exhibit_torus_knot"] == "simplified" and kinds["distant_hills"] == "simplified"
    assert kinds["floor_parquet"] == "box" and kinds["calibration_cube"] == "box"
    total = sum(r.triangles_proxy for r in results.values())
    assert total < 0.02 * room.triangle_count


def test_torus_knot_at_full_resolution(room):
    knot = next(o for o in room.objects if o.name == "exhibit_torus_knot").mesh
    r = simplify_encaging(knot, resolution=128, target_fraction=0.005)
    assert_valid(r, knot)
    assert r.kind == "simplified"
    assert r.params["target_triangles"] == 128 and 120 <= r.triangles_proxy <= 160
    assert r.params["volume_ratio_to_box"] < 0.6


def test_thin_balusters_and_cables_are_encaged(room):
    for name, fraction in (("railing_balusters", 0.02), ("lamp_1_cable", 0.5)):
        mesh = next(o for o in room.objects if o.name == name).mesh
        r = simplify_encaging(mesh, resolution=64, target_fraction=fraction)
        assert_valid(r, mesh)


# ----------------------------------------------------------------------------- edge cases

def test_mesh_without_faces():
    for vertices in (np.zeros((0, 3)), np.random.default_rng(1).normal(size=(5, 3))):
        mesh = Mesh(vertices, np.zeros((0, 3), np.uint32))
        r = simplify_encaging(mesh)
        assert r.kind == "empty" and r.triangles_proxy == 0 and r.enclosed_fraction == 1.0
        assert "no faces" in r.note


def test_flat_plane_gets_a_thin_closed_encaging_proxy():
    plane = prim.grid_plane(2.0, 1.0, cell_size=0.05)            # 1 600 triangles at y = 0
    voxel = 2.0 / 32
    # the voxel hull of a zero-thickness plane is a closed slab a voxel or two thick
    f = plane.faces.astype(np.int64)
    lo, hi = plane.bounds().astype(np.float64)
    grid_lo = lo - lod.PADDING_VOXELS * voxel
    dims = np.floor((hi - lo) / voxel).astype(np.int64) + 1 + 2 * lod.PADDING_VOXELS
    hv, hf = lod.hull_surface(lod.voxel_hull(plane.vertices, f, grid_lo, voxel, dims), grid_lo, voxel)
    assert is_watertight(hf) and signed_volume(hv, hf) > 0
    assert np.ptp(hv[:, 1]) <= 2 * voxel + 1e-9
    # marching cubes cuts the slab's corners, so the hull alone is not conservative there:
    # within a voxel, not within tolerance -- which is why the proxy is encaged afterwards
    _, enclosed = measure_enclosure(plane.vertices.astype(np.float64), hv, hf, voxel)
    assert enclosed.all()
    # the result: closed, encaging, thin (here the box, a tolerance-thick slab, beats the hull)
    r = simplify_encaging(plane, resolution=32, target_fraction=0.05)
    assert_valid(r, plane)
    assert np.ptp(r.proxy.vertices[:, 1]) <= 2 * voxel


def test_zero_area_triangles_and_collapsed_meshes():
    box = prim.box((1.0, 0.5, 0.25))
    v = np.vstack([box.vertices, [[0.2, 0.3, 0.0], [0.4, 0.3, 0.0], [0.6, 0.3, 0.0], [0.1, 0.1, 0.1]]])
    n = len(box.vertices)
    slivers = np.array([[n, n + 1, n + 2], [n + 3, n + 3, n + 3], [n, n, n + 1]])   # collinear, point, edge
    mesh = Mesh(v, np.vstack([box.faces, slivers]))
    assert_valid(simplify_encaging(mesh, resolution=32, target_fraction=0.5), mesh)
    # every triangle degenerate, all on one line: a proxy that still has a (thin) inside
    line = Mesh([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]] * 30)
    r = simplify_encaging(line, resolution=16, target_fraction=1.0)
    assert_valid(r, line)
    assert signed_volume(r.proxy.vertices, r.proxy.faces) > 0
    # a mesh collapsed to a single point (smaller than any voxel)
    point = Mesh([[3.0, 4.0, 5.0]] * 3, [[0, 1, 2]])
    r = simplify_encaging(point)
    assert r.kind == "box" and "coincide" in r.note
    assert_valid(r, point)


def test_open_mesh_is_encaged():
    tube = prim.cylinder(0.3, 1.0, 48, caps=False, height_segments=24)   # open at both ends
    # the flood fill enters through the open ends: the hull is a hollow shell, not a solid
    r = simplify_encaging(tube, resolution=48, target_fraction=0.1)
    assert_valid(r, tube)
    assert r.kind == "simplified"


def test_box_when_simplification_cannot_beat_it():
    cube = prim.box((1.0, 2.0, 3.0), max_cell=0.5)                        # a few hundred triangles
    r = simplify_encaging(cube, target_fraction=0.005)
    assert r.kind == "box" and r.triangles_proxy == 12 and "box's 12" in r.note
    np.testing.assert_allclose(r.box.vertices.min(0), [-0.5, -1.0, -1.5], atol=1e-6)
    np.testing.assert_allclose(r.box.vertices.max(0), [0.5, 1.0, 1.5], atol=1e-6)


def test_invalid_parameters_are_rejected():
    mesh = prim.box()
    for kwargs in ({"resolution": 2}, {"resolution": 32.5}, {"target_fraction": 0.0}, {"target_fraction": 1.5},
                   {"min_triangles": 2}, {"tolerance": -1.0}, {"tolerance": float("nan")}, {"max_iterations": -1}):
        with pytest.raises(SceneError):
            simplify_encaging(mesh, **kwargs)


def test_deterministic():
    mesh = load_scene(str(SPOT)).objects[0].mesh
    a = simplify_encaging(mesh, resolution=64, target_fraction=0.005)
    b = simplify_encaging(mesh, resolution=64, target_fraction=0.005)
    np.testing.assert_array_equal(a.proxy.vertices, b.proxy.vertices)
    np.testing.assert_array_equal(a.proxy.faces, b.proxy.faces)
    assert a.iterations == b.iterations and a.enclosed_fraction == b.enclosed_fraction


def test_real_asset_at_full_resolution():
    scene = load_scene(str(SPOT))
    assert len(scene.objects) == 1
    mesh = scene.objects[0].mesh
    assert mesh.triangle_count == 5856 and is_watertight(mesh.faces)
    stages = []
    r = simplify_encaging(mesh, resolution=128, target_fraction=0.005, progress=stages.append)
    assert_valid(r, mesh)
    assert r.kind == "simplified" and r.params["target_triangles"] == 30
    assert any(s.startswith("voxelize") for s in stages) and "measure" in stages


# ----------------------------------------------------------------------------- cache

def test_cache_hit_skips_generation_and_round_trips(cache_dir):
    mesh = prim.torus(0.3, 0.08, 96, 32)
    before = lod_cache.cache_stats()
    first = lod_cache.cached_lod(mesh, resolution=32, target_fraction=0.01)
    mid = lod_cache.cache_stats()
    assert mid["generated"] == before["generated"] + 1 and mid["files"] == 1
    assert mid["directory"] == str(cache_dir)
    second = lod_cache.cached_lod(mesh, resolution=32, target_fraction=0.01)
    after = lod_cache.cache_stats()
    assert after["generated"] == mid["generated"] and after["hits"] == mid["hits"] + 1
    np.testing.assert_array_equal(first.proxy.vertices, second.proxy.vertices)
    np.testing.assert_array_equal(first.proxy.faces, second.proxy.faces)
    for field in ("kind", "note", "enclosed_fraction", "max_outside_distance", "iterations", "seconds", "params"):
        assert getattr(first, field) == getattr(second, field)
    # other parameters, other entry
    lod_cache.cached_lod(mesh, resolution=32, target_fraction=0.02)
    assert lod_cache.cache_stats()["files"] == 2
    assert not list(cache_dir.glob("*.tmp"))                 # atomic writes leave nothing behind


@pytest.mark.parametrize("damage", ["garbage", "truncated", "other_entry"])
def test_corrupted_cache_file_is_regenerated(cache_dir, caplog, damage):
    mesh = prim.torus(0.3, 0.08, 96, 32)
    good = lod_cache.cached_lod(mesh, resolution=32, target_fraction=0.01)
    key = lod_cache.cache_key(mesh, resolution=32, target_fraction=0.01, min_triangles=12, tolerance=None,
                              max_iterations=lod.DEFAULT_MAX_ITERATIONS)
    path = cache_dir / f"{key}.npz"
    assert path.is_file()
    if damage == "garbage":
        path.write_bytes(b"not an npz at all")
    elif damage == "truncated":
        path.write_bytes(path.read_bytes()[:200])
    else:  # a valid file of another mesh under this name
        other = lod_cache.cached_lod(prim.sphere(0.4, 24, 12), resolution=32, target_fraction=0.05)
        assert other.triangles_original != good.triangles_original
        other_path = next(p for p in cache_dir.glob("*.npz") if p != path)
        path.write_bytes(other_path.read_bytes())
    before = lod_cache.cache_stats()
    with caplog.at_level(logging.WARNING, logger="pibr.scenes.lod_cache"):
        again = lod_cache.cached_lod(mesh, resolution=32, target_fraction=0.01)
    after = lod_cache.cache_stats()
    assert after["corrupted"] == before["corrupted"] + 1 and after["generated"] == before["generated"] + 1
    assert "corrupted" in caplog.text and path.name in caplog.text
    np.testing.assert_array_equal(again.proxy.faces, good.proxy.faces)
    assert lod_cache.cached_lod(mesh, resolution=32, target_fraction=0.01).kind == good.kind   # readable again
    assert lod_cache.cache_stats()["hits"] == after["hits"] + 1


def test_scene_lods_never_regenerate_cached_meshes(cache_dir):
    scene = load_scene("sphere")
    first = lod_cache.lods_for_scene(scene, resolution=32, target_fraction=0.02, progress=False)
    generated = lod_cache.cache_stats()["generated"]
    second = lod_cache.lods_for_scene(scene, resolution=32, target_fraction=0.02, progress=True)
    assert lod_cache.cache_stats()["generated"] == generated
    assert first.keys() == second.keys() == {"sphere"}
    np.testing.assert_array_equal(first["sphere"].proxy.faces, second["sphere"].proxy.faces)


def test_cache_dir_default(monkeypatch):
    monkeypatch.delenv(lod_cache.ENV_VAR, raising=False)
    assert lod_cache.cache_dir() == Path.home() / ".cache" / "pibr" / "lod"


# ----------------------------------------------------------------------------- benchmark

def test_lod_bench_writes_json_and_table(tmp_path, capsys, cache_dir):
    from pibr.bench.lod_bench import print_lod_table, run_lod_bench

    result = run_lod_bench(scene_specs=("sphere",), assets=(str(SPOT),), resolution=32, target_fraction=0.005,
                           out_dir=str(tmp_path))
    # it goes through the LoD cache: a second run generates nothing and reads the same proxies
    generated = lod_cache.cache_stats()["generated"]
    again = run_lod_bench(scene_specs=("sphere",), assets=(str(SPOT),), resolution=32, target_fraction=0.005,
                          out_dir=str(tmp_path))
    assert lod_cache.cache_stats()["generated"] == generated and again["totals"] == result["totals"]
    assert result["cached"] is True
    saved = json.loads((tmp_path / "lod.json").read_text())
    assert saved["totals"] == result["totals"]
    assert [s["scene"] for s in result["scenes"]] == ["sphere", "spot_triangulated"]
    rows = [r for s in result["scenes"] for r in s["objects"]]
    assert result["totals"]["triangles_original"] == sum(r["triangles_original"] for r in rows) == 3968 + 5856
    assert all(r["enclosed_fraction"] == 1.0 for r in rows)
    print_lod_table(result)
    out = capsys.readouterr().out
    assert "spot_triangulated" in out and "total" in out


def test_cache_metadata_is_read_with_the_bounded_reader(tmp_path):
    """A cache file whose metadata nests deeply is damage (ValueError), not a RecursionError."""
    faces = np.zeros((1, 3), np.int64)
    verts = np.zeros((3, 3))
    for meta, problem in ((b"[" * 100_000 + b"]" * 100_000, "nested deeper than 32 levels"),
                          (b'{"enclosed_fraction": NaN}', "NaN is not a finite number"),
                          (b'{"iterations": ' + b"9" * 5000 + b"}", "a number of 5000 characters")):
        path = tmp_path / "entry.npz"
        np.savez(path, proxy_vertices=verts, proxy_faces=faces, box_vertices=verts, box_faces=faces,
                 meta=np.frombuffer(meta, np.uint8))
        with pytest.raises(ValueError, match=f"bad metadata: metadata: .*{problem}"):
            lod_cache._decode(path, "key")
