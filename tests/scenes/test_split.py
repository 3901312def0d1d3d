"""Level-sized meshes cut into spatially coherent pieces, and their LoDs built in parallel."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from pibr.protocol.errors import SceneError
from pibr.scenes import lod_cache
from pibr.scenes.registry import load_scene
from pibr.scenes.split import split_arrays, split_faces


def long_hall() -> trimesh.Trimesh:
    """A 40 m x 4 m x 3 m open box, finely tessellated, as one mesh (3 072 triangles)."""
    box = trimesh.creation.box((40.0, 3.0, 4.0))
    for _ in range(4):
        box = box.subdivide()
    return box


def test_pieces_cover_every_triangle_once_and_are_compact():
    hall = long_hall()
    centroids = hall.triangles_center
    pieces = split_faces(centroids, 500)
    assert all(len(p) <= 500 for p in pieces) and len(pieces) == 8
    assert np.array_equal(np.sort(np.concatenate(pieces)), np.arange(len(centroids)))
    # spatially coherent: each piece spans a fraction of the hall's length
    spans = [np.ptp(centroids[p][:, 0]) for p in pieces]
    assert max(spans) < 0.4 * np.ptp(centroids[:, 0])
    (whole,) = split_faces(centroids, 10_000)
    assert np.array_equal(whole, np.arange(len(centroids)))


def test_split_arrays_carries_vertex_attributes():
    hall = long_hall()
    v, f = np.asarray(hall.vertices), np.asarray(hall.faces)
    uv = v[:, :2] * 0.1
    pieces = split_arrays(v, f, {"uvs": uv, "normals": None}, 1000)
    assert sum(len(pf) for _, pf, _ in pieces) == len(f)
    for pv, pf, attrs in pieces:
        assert pf.max() == len(pv) - 1 and attrs["normals"] is None
        np.testing.assert_array_equal(attrs["uvs"], pv[:, :2] * 0.1)   # each vertex kept its own UV


def test_an_asset_is_cut_unless_told_not_to(tmp_path):
    path = tmp_path / "hall.ply"
    long_hall().export(path)
    cut = load_scene(f"{path}#up=y,split=500")
    assert len(cut.objects) == 8 and cut.triangle_count == 3072
    assert len({o.name for o in cut.objects}) == 8
    assert any("cut into pieces of at most 500 triangles: hall (3072 triangles) into 8" in n for n in cut.notes)
    whole = load_scene(f"{path}#up=y,split=0")
    assert len(whole.objects) == 1 and whole.triangle_count == 3072
    assert len(load_scene(f"{path}#up=y").objects) == 1        # below the default piece size
    with pytest.raises(SceneError, match="split must be a whole number"):
        load_scene(f"{path}#split=lots")
    desc = tmp_path / "hall.toml"
    desc.write_text('name = "hall"\n[[objects]]\nasset = "hall.ply"\nup = "y"\nsplit = 1000\n')
    assert len(load_scene(str(desc)).objects) == 4


def test_pieces_get_their_lods_in_parallel_as_they_would_one_by_one(tmp_path, monkeypatch):
    path = tmp_path / "hall.ply"
    long_hall().export(path)
    scene = load_scene(f"{path}#up=y,split=800")
    monkeypatch.setenv(lod_cache.ENV_VAR, str(tmp_path / "a"))
    parallel = lod_cache.lods_for_scene(scene, resolution=24, target_fraction=0.05, progress=False, workers=2)
    monkeypatch.setenv(lod_cache.ENV_VAR, str(tmp_path / "b"))
    serial = lod_cache.lods_for_scene(scene, resolution=24, target_fraction=0.05, progress=False, workers=1)
    assert list(parallel) == list(serial) == [o.name for o in scene.objects]
    for name in parallel:
        np.testing.assert_array_equal(parallel[name].proxy.faces, serial[name].proxy.faces)
        np.testing.assert_array_equal(parallel[name].proxy.vertices, serial[name].proxy.vertices)
    assert len(list((tmp_path / "a").glob("*.npz"))) == len(scene.objects)   # the workers filled the cache
