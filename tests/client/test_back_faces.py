"""Which meshes may skip their back faces, and from where (client/back_faces.py)."""
import numpy as np

from pibr.client.back_faces import BackFaceTest
from pibr.protocol.proxy import ProxyObject, winds_outward
from pibr.scenes import primitives as prim

_BOX = ProxyObject("b", np.eye(4), False, np.array([[-1.0, -1, -1], [1, 1, 1]]), ((), ()), ((), ())).box_mesh()


def _split(vertices, faces):
    """Every face with vertices of its own (as meshes split them along uv seams)."""
    return vertices[faces].reshape(-1, 3), np.arange(3 * len(faces), dtype=np.uint32).reshape(-1, 3)


def test_closed_outward_meshes_qualify_and_others_do_not():
    v, f = _BOX
    assert winds_outward(v, f)
    assert winds_outward(*_split(v, f))                 # vertices merged by position
    assert not winds_outward(v, f[:, ::-1])             # wound inward
    assert not winds_outward(v, f[:-2])                 # a side missing: open
    assert not winds_outward(v, f[:0])
    knot = prim.torus_knot(radius=0.3, tube_radius=0.05, segments=64, tube_segments=8)
    assert winds_outward(knot.vertices, knot.faces)
    # a box and an inside-out box apart from it: the sum is positive, a part is not
    far = v + np.array([5.0, 0.0, 0.0], np.float32)
    assert not winds_outward(np.vstack([v * 2, far]), np.vstack([f, f[:, ::-1] + len(v)]))
    # an outward box with a two-sided sheet (volume 0) apart from it
    sheet_v = np.array([[3, 0, 0], [4, 0, 0], [4, 1, 0], [3, 1, 0]], np.float32)
    sheet_f = np.array([[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]], np.uint32) + len(v)
    assert winds_outward(np.vstack([v, sheet_v]), np.vstack([f, sheet_f]))
    assert not winds_outward(sheet_v, sheet_f - len(v))  # a sheet alone encloses nothing


def test_the_eye_must_be_outside_the_mesh_and_beyond_the_near_plane():
    v, f = _BOX
    box = BackFaceTest(v, f)
    eye = np.eye(4)
    assert box.allows(np.array([0.0, 0.0, 5.0]), eye, 0.1)
    assert not box.allows(np.array([0.0, 0.0, 0.5]), eye, 0.1)       # inside
    assert not box.allows(np.array([0.0, 0.0, 1.05]), eye, 0.1)      # the near plane cuts the side
    assert box.allows(np.array([0.0, 0.0, 1.05]), eye, 0.01)
    assert not BackFaceTest(v, f, enabled=False).allows(np.array([0.0, 0.0, 5.0]), eye, 0.1)
    assert not BackFaceTest(v, f[:-2]).allows(np.array([0.0, 0.0, 5.0]), eye, 0.1)
    # placements: moved and scaled (the reach is measured in world units), mirrored
    placed = np.diag([2.0, 2.0, 2.0, 1.0])
    placed[:3, 3] = (10.0, 0.0, 0.0)
    assert not placed_allows(box, (10.0, 0.0, 1.5), placed, 0.1)    # inside the scaled box
    assert not placed_allows(box, (10.0, 0.0, 2.05), placed, 0.1)
    assert placed_allows(box, (10.0, 0.0, 2.5), placed, 0.1)
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    assert not placed_allows(box, (0.0, 0.0, 5.0), mirror, 0.1)
    # inside a torus's box, in its hole: outside the mesh; inside its tube: not
    torus = prim.torus(1.0, 0.2, 48, 16)
    t = BackFaceTest(torus.vertices, torus.faces)
    assert t.allows(np.array([0.0, 0.0, 0.0]), eye, 0.1)
    assert not t.allows(np.array([1.0, 0.0, 0.0]), eye, 0.01)
    assert not t.allows(np.array([0.0, 0.0, 0.0]), eye, 0.85)        # the near plane reaches the tube


def placed_allows(test, eye, model, reach):
    return test.allows(np.array(eye, np.float64), model, reach)
