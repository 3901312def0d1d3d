"""The OBJECT_POSES payload: moving objects' transforms per frame, validated on parse."""
import hashlib
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pibr.protocol.errors import MalformedMessage, ProtocolError
from pibr.protocol.messages import Frame, PayloadKind
from pibr.protocol.object_poses import ENTRY_BYTES, ObjectPoses, decode_object_poses, encode_object_poses
from pibr.protocol.pose import Pose, quat_from_axis_angle, quat_to_matrix


def _poses() -> ObjectPoses:
    q = np.stack([quat_from_axis_angle((0, 1, 0), 0.5), quat_from_axis_angle((1, 1, 0), 3.1)])
    return ObjectPoses(np.array([2, 7]), np.array([[0.5, -1.25, 3.0], [100.0, 2.0, -0.125]]), q)


def test_round_trip_and_matrices():
    poses = _poses()
    data = encode_object_poses(poses)
    assert len(data) == 4 + 2 * ENTRY_BYTES and ENTRY_BYTES == 32
    back = decode_object_poses(data, object_count=8)
    assert back.indices.tolist() == [2, 7]
    np.testing.assert_allclose(back.positions, poses.positions, atol=1e-5)
    np.testing.assert_allclose(back.orientations, poses.orientations, atol=1e-7)
    np.testing.assert_allclose(np.linalg.norm(back.orientations, axis=1), 1.0, atol=1e-15)
    m = back.matrices()
    assert m.shape == (2, 4, 4)
    np.testing.assert_allclose(m[1, :3, :3], quat_to_matrix(poses.orientations[1]), atol=1e-6)
    np.testing.assert_allclose(m[0, :3, 3], poses.positions[0])
    again = ObjectPoses.from_matrices(back.indices, m)
    np.testing.assert_allclose(again.matrices(), m, atol=1e-12)
    empty = decode_object_poses(encode_object_poses(ObjectPoses(np.zeros(0, int), np.zeros((0, 3)),
                                                                np.zeros((0, 4)))), 0)
    assert len(empty) == 0 and empty.matrices().shape == (0, 4, 4)


def test_golden_bytes_are_stable():
    data = encode_object_poses(_poses())
    # Pinned: a change here changes the wire format both ends must agree on.
    assert hashlib.sha256(data).hexdigest() == "c1a48ef89a698790f70052944c4429926d61c8834998fd0dfe699844e58aa5ce"
    assert encode_object_poses(decode_object_poses(data, 8)) == data


def _entry(index, position, q) -> bytes:
    return struct.pack("<I3f4f", index, *position, *q)


def _payload(*entries) -> bytes:
    return struct.pack("<I", len(entries)) + b"".join(entries)


@pytest.mark.parametrize("data, count, message", [
    (b"\x01\x00", 4, "shorter than the 4-byte count"),
    (_payload(_entry(0, (0, 0, 0), (1, 0, 0, 0))) + b"x", 4, "need 36 bytes, got 37"),
    (_payload(_entry(0, (0, 0, 0), (1, 0, 0, 0)))[:-1], 4, "need 36 bytes, got 35"),
    (struct.pack("<I", 5) + bytes(5 * ENTRY_BYTES), 4, "5 poses for a scene of 4 objects"),
    (struct.pack("<I", 2 ** 32 - 1), 4, "4294967295 poses for a scene of 4 objects"),
    (_payload(_entry(4, (0, 0, 0), (1, 0, 0, 0))), 4, "object index 4 is not below the object count 4"),
    (_payload(_entry(2, (0, 0, 0), (1, 0, 0, 0)), _entry(1, (0, 0, 0), (1, 0, 0, 0))), 4, "strictly increasing"),
    (_payload(_entry(2, (0, 0, 0), (1, 0, 0, 0)), _entry(2, (0, 0, 0), (1, 0, 0, 0))), 4, "strictly increasing"),
    (_payload(_entry(1, (0, float("nan"), 0), (1, 0, 0, 0))), 4, "object 1 has a non-finite position"),
    (_payload(_entry(3, (0, 0, 0), (float("inf"), 0, 0, 0))), 4, "object 3 has a non-finite position or quat"),
    (_payload(_entry(0, (0, 0, 0), (0, 0, 0, 0))), 4, "object 0 quaternion has norm 0, not 1"),
    (_payload(_entry(0, (0, 0, 0), (1.01, 0, 0, 0))), 4, "object 0 quaternion has norm 1.01, not 1"),
])
def test_bad_payloads_name_the_problem(data, count, message):
    with pytest.raises(MalformedMessage, match=message) as info:
        decode_object_poses(data, count)
    assert isinstance(info.value, ProtocolError)
    assert str(info.value).startswith("Frame object poses:")


def test_unit_tolerance_admits_float32_rounding():
    q = np.array([0.70710678, 0.70710678, 0.0, 0.0], np.float32)   # norm 1 - 3e-8 in float32
    back = decode_object_poses(_payload(_entry(0, (1, 2, 3), q)), 1)
    assert abs(np.linalg.norm(back.orientations[0]) - 1.0) < 1e-15


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200), st.integers(0, 6))
def test_garbage_never_crashes(data, count):
    for d in (data, struct.pack("<I", len(data) // ENTRY_BYTES) + data):
        try:
            poses = decode_object_poses(d, count)
        except MalformedMessage:
            continue
        assert len(poses) <= count and np.all(np.isfinite(poses.matrices()))


def test_a_frame_carries_them_as_its_own_payload_kind():
    data = encode_object_poses(_poses())
    frame = Frame(1, 100_000, 90_000, 3, 100_000, Pose.identity(), None, 0.1, 100.0,
                  payloads=((PayloadKind.H264_ATLAS, b"h264"), (PayloadKind.OBJECT_POSES, data)))
    back = Frame.parse(frame.serialize())
    assert back.payload(PayloadKind.OBJECT_POSES) == data
    assert PayloadKind.NAMES[PayloadKind.OBJECT_POSES] == "object-poses"
