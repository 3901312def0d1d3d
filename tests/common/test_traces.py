"""Head traces: canonical CSV, importers, resampling, synthesis and the ``pibr trace`` commands."""
from __future__ import annotations

import argparse
import json
import math
from importlib import resources

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pibr.protocol.errors import ConfigError, TraceError
from pibr.common.traces.canonical import CANONICAL_HEADER, read_canonical_csv, write_canonical_csv
from pibr.common.traces.importers import import_csv, import_pred6dof, parse_columns
from pibr.common.traces.loading import builtin_traces, load_trace
from pibr.common.traces.synthesis import synthesize
from pibr.protocol.pose import quat_angle, quat_from_axis_angle, quat_normalize, quat_rotate, quat_to_matrix
from pibr.protocol.trace import HeadTrace, yaw_pitch

from ..protocol.pose_reference import left_handed_to_right_handed

PRED6DOF_HEADER = "timestamp,x,y,z,qx,qy,qz,qw"


def builtin_file(name: str):
    return resources.files("pibr.common.traces").joinpath("data", "pred6dof", name)


def random_trace(n=50, seed=0) -> HeadTrace:
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.001, 0.05, n))
    return HeadTrace.from_samples(t, rng.normal(size=(n, 3)), rng.normal(size=(n, 4)), "random")


def write(path, text: str):
    path.write_text(text)
    return path


# --------------------------------------------------------------------------------- canonical CSV


def test_canonical_round_trip_is_exact(tmp_path):
    trace = random_trace()
    path = tmp_path / "walk.csv"
    write_canonical_csv(trace, path)
    assert path.read_text().splitlines()[0] == CANONICAL_HEADER
    back = read_canonical_csv(path)
    assert back.name == "walk"
    for a, b in ((trace.t, back.t), (trace.positions, back.positions), (trace.orientations, back.orientations)):
        assert a.dtype == b.dtype == np.float64
        assert np.array_equal(a, b)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.integers(1, 20), st.integers(0, 2**32 - 1))
def test_canonical_round_trip_property(tmp_path, n, seed):
    trace = random_trace(n, seed)
    path = tmp_path / "t.csv"
    write_canonical_csv(trace, path)
    back = read_canonical_csv(path)
    assert np.array_equal(back.t, trace.t)
    assert np.array_equal(back.positions, trace.positions)
    assert np.array_equal(back.orientations, trace.orientations)


def test_canonical_read_rebases_time_and_normalises(tmp_path):
    path = write(tmp_path / "a.csv", f"{CANONICAL_HEADER}\n10,1,2,3,2,0,0,0\n10.5,1,2,3,0,0,-3,0\n\n")
    trace = read_canonical_csv(path)
    np.testing.assert_array_equal(trace.t, [0.0, 0.5])
    np.testing.assert_allclose(trace.orientations, [[1, 0, 0, 0], [0, 0, 1, 0]])


GOOD = "0,0,0,0,1,0,0,0\n"


@pytest.mark.parametrize("rows, line, fragment", [
    (GOOD + "0.1,abc,0,0,1,0,0,0\n", 3, "'abc' is not a number"),
    (GOOD + "0.1,0,nan,0,1,0,0,0\n", 3, "NaN"),
    (GOOD + "0.1,0,0,inf,1,0,0,0\n", 3, "infinite"),
    (GOOD + "0.1,0,0,0,0,0,0,0\n", 3, "zero quaternion"),
    (GOOD + "0.2,0,0,0,1,0,0,0\n0.1,0,0,0,1,0,0,0\n", 4, "not increasing"),
    (GOOD + "0.1,0,0,0,1,0,0,0\n0.1,0,0,0,1,0,0,0\n", 4, "duplicate timestamp"),
    (GOOD + "0.1,0,0,0,1,0,0\n", 3, "expected 8 columns"),
    (GOOD + "\n\n0.1,0,0,0,1,0,0,0,9\n", 5, "got 9"),  # blank lines still count
])
def test_canonical_errors_name_file_and_line(tmp_path, rows, line, fragment):
    path = write(tmp_path / "bad.csv", CANONICAL_HEADER + "\n" + rows)
    with pytest.raises(TraceError) as info:
        read_canonical_csv(path)
    message = str(info.value)
    assert f"line {line}:" in message
    assert fragment in message
    assert "bad.csv" in message


def test_canonical_header_and_empty_errors(tmp_path):
    with pytest.raises(TraceError, match="line 1: header must be exactly"):
        read_canonical_csv(write(tmp_path / "h.csv", "t,x,y,z,qw,qx,qy,qz\n" + GOOD))
    with pytest.raises(TraceError, match="empty file"):
        read_canonical_csv(write(tmp_path / "e.csv", "\n"))
    with pytest.raises(TraceError, match="no samples"):
        read_canonical_csv(write(tmp_path / "n.csv", CANONICAL_HEADER + "\n"))
    with pytest.raises(TraceError, match="no such trace file"):
        read_canonical_csv(tmp_path / "missing.csv")


# --------------------------------------------------------------------------------- HeadTrace


def test_headtrace_validates():
    t, p, q = np.array([0.0, 1.0]), np.zeros((2, 3)), np.tile([1.0, 0, 0, 0], (2, 1))
    HeadTrace(t, p, q, "ok")
    with pytest.raises(TraceError, match=r"positions must have shape \(2, 3\)"):
        HeadTrace(t, np.zeros((2, 2)), q)
    with pytest.raises(TraceError, match=r"orientations must have shape \(2, 4\)"):
        HeadTrace(t, p, q[:, :3])
    with pytest.raises(TraceError, match="start at 0"):
        HeadTrace(t + 1, p, q)
    with pytest.raises(TraceError, match="strictly increasing"):
        HeadTrace(np.array([0.0, 0.0]), p, q)
    with pytest.raises(TraceError, match="NaN"):
        HeadTrace(t, np.array([[0, 0, 0], [0, np.nan, 0]]), q)
    with pytest.raises(TraceError, match="unit quaternions"):
        HeadTrace(t, p, 2 * q)
    with pytest.raises(TraceError, match="zero quaternion|norm"):
        HeadTrace.from_samples(t, p, np.zeros((2, 4)))
    trace = HeadTrace(t, p, q)
    with pytest.raises(ValueError):
        trace.t[0] = 5.0  # stored read-only


def two_sample_trace() -> HeadTrace:
    q_end = quat_from_axis_angle((0, 1, 0), math.pi / 2)
    return HeadTrace(np.array([0.0, 1.0]), np.array([[0.0, 0, 0], [1.0, 2.0, 3.0]]),
                     np.array([[1.0, 0, 0, 0], q_end]), "two")


def test_sample_linear_position_slerp_orientation_and_clamping():
    trace = two_sample_trace()
    p, q = trace.sample([0.25, 0.5])
    np.testing.assert_allclose(p, [[0.25, 0.5, 0.75], [0.5, 1.0, 1.5]])
    np.testing.assert_allclose(quat_normalize(q[1]), quat_from_axis_angle((0, 1, 0), math.pi / 4), atol=1e-12)
    np.testing.assert_allclose(quat_angle(q[0], [1, 0, 0, 0]), math.pi / 8, atol=1e-12)
    p, q = trace.sample([-3.0, 7.0])
    np.testing.assert_array_equal(p, trace.positions)
    np.testing.assert_allclose(q, trace.orientations, atol=1e-15)
    pose = trace.pose_at(0.5)
    np.testing.assert_allclose(pose.forward(), [-math.sin(math.pi / 4), 0, -math.cos(math.pi / 4)], atol=1e-12)


def test_resample_rate_is_exact():
    trace = two_sample_trace()
    r = trace.resample(10)
    assert len(r) == 11
    np.testing.assert_array_equal(r.t, np.arange(11) / 10)
    np.testing.assert_allclose(r.positions[:, 0], np.arange(11) / 10)
    np.testing.assert_allclose(np.degrees(yaw_pitch(r.orientations)[:, 0]), np.arange(11) * 9.0, atol=1e-9)
    third = trace.resample(3)  # the end at exactly 3 / 3 s is kept despite rounding
    np.testing.assert_array_equal(third.t, np.arange(4) / 3)
    part = trace.resample(100, start=0.2, duration=0.5)
    assert len(part) == 51 and part.t[0] == 0.0
    np.testing.assert_allclose(part.positions[[0, -1], 0], [0.2, 0.7])
    with pytest.raises(TraceError, match="positive"):
        trace.resample(0)
    with pytest.raises(TraceError, match="outside"):
        trace.resample(10, start=2.0)


def test_resample_real_trace_and_slice():
    trace = load_trace("pred6dof-2")
    r = trace.resample(90)
    assert np.allclose(np.diff(r.t), 1 / 90)
    assert r.duration == pytest.approx(trace.duration, abs=1 / 90)
    np.testing.assert_allclose(np.linalg.norm(r.orientations, axis=1), 1.0, atol=1e-12)
    s = trace.slice(10.0, 5.0)
    assert s.t[0] == 0.0 and s.duration == pytest.approx(5.0)
    np.testing.assert_allclose(s.positions[0], trace.sample(10.0)[0])
    inner = trace.t[(trace.t > 10.0) & (trace.t < 15.0)]
    np.testing.assert_allclose(s.t[1:-1], inner - 10.0)


def test_speeds_and_summary():
    trace = two_sample_trace()
    linear, angular = trace.speeds()
    np.testing.assert_allclose(linear, [math.sqrt(14)])
    np.testing.assert_allclose(angular, [math.pi / 2])
    info = trace.summary()
    assert info["samples"] == 2 and info["duration_s"] == 1.0
    assert info["median_rate_hz"] == pytest.approx(1.0)
    assert info["linear_speed_m_s"]["max"] == pytest.approx(math.sqrt(14))
    assert info["angular_speed_deg_s"]["max"] == pytest.approx(90.0)
    assert info["position_extent"] == [1.0, 2.0, 3.0]
    json.dumps(info)


# --------------------------------------------------------------------------------- pred6dof


@pytest.mark.parametrize("name, duration, samples", [("pred6dof-1", 77.70028, 4664),
                                                     ("pred6dof-2", 72.3565636, 4343)])
def test_builtin_pred6dof(name, duration, samples):
    trace = load_trace(name)
    assert trace.name == name
    assert len(trace) == samples
    assert trace.duration == pytest.approx(duration, abs=1e-6)
    assert trace.t[0] == 0.0 and np.all(np.diff(trace.t) > 0)
    np.testing.assert_allclose(np.linalg.norm(trace.orientations, axis=1), 1.0, atol=1e-12)
    assert trace.warnings == []  # the real files have no repeated or backwards timestamps
    assert name in builtin_traces()


def test_pred6dof_conversion_to_right_handed():
    trace = import_pred6dof(builtin_file("1.csv"))
    lines = builtin_file("1.csv").read_text().splitlines()
    t0 = int(lines[1].split(",")[0])
    # Line 2000 is sample 1998: a head turned ~80 degrees in Unity.
    fields = lines[1999].split(",")
    ticks = int(fields[0])
    x, y, z, qx, qy, qz, qw = map(float, fields[1:])
    i = 1998
    assert trace.t[i] == (ticks - t0) / 1e7  # integer ticks: no precision lost to 6e17
    np.testing.assert_allclose(trace.positions[i], [x, y, -z], rtol=0, atol=1e-12)
    unity_forward = quat_to_matrix(quat_normalize([qw, qx, qy, qz])) @ [0.0, 0.0, 1.0]
    pibr_forward = quat_rotate(trace.orientations[i], [0.0, 0.0, -1.0])
    np.testing.assert_allclose(pibr_forward, unity_forward * [1, 1, -1], atol=1e-7)
    assert abs(unity_forward[0]) > 0.9  # the sample really is turned, the check is not trivial


def test_pred6dof_duplicates_dropped_backwards_rejected(tmp_path):
    rows = ["1000000, 0, 0, 0, 0, 0, 0, 1", "1100000, 1, 0, 0, 0, 0, 0, 1",
            "1100000, 2, 0, 0, 0, 0, 0, 1", "1200000, 3, 0, 0, 0, 0, 0, 1"]
    trace = import_pred6dof(write(tmp_path / "d.csv", PRED6DOF_HEADER + "\n" + "\n".join(rows) + "\n"))
    assert len(trace) == 3
    np.testing.assert_allclose(trace.t, [0.0, 0.01, 0.02])
    np.testing.assert_allclose(trace.positions[:, 0], [0.0, 1.0, 3.0])  # the first of the pair is kept
    assert len(trace.warnings) == 1 and "dropped 1" in trace.warnings[0] and "line 4" in trace.warnings[0]

    rows[3] = "1050000, 3, 0, 0, 0, 0, 0, 1"
    with pytest.raises(TraceError, match="line 5: time goes backwards"):
        import_pred6dof(write(tmp_path / "b.csv", PRED6DOF_HEADER + "\n" + "\n".join(rows)))
    with pytest.raises(TraceError, match="line 3: timestamp 1500000.0 mixes decimal and integer timestamps"):
        import_pred6dof(write(tmp_path / "f.csv", PRED6DOF_HEADER + "\n1000000, 0, 0, 0, 0, 0, 0, 1\n"
                                                                   "1.5e6, 0, 0, 0, 0, 0, 0, 1\n"))
    seconds = import_pred6dof(write(tmp_path / "s.csv", PRED6DOF_HEADER + "\n10.5, 0, 0, 0, 0, 0, 0, 1\n"
                                                                        "10.75, 0, 0, 0, 0, 0, 0, 1\n"))
    np.testing.assert_allclose(seconds.t, [0.0, 0.25])      # decimals are seconds, and say so
    assert seconds.assumptions["time"] == "column 'timestamp' in seconds (from its decimal values)"
    with pytest.raises(TraceError, match="line 2: zero quaternion"):
        import_pred6dof(write(tmp_path / "z.csv", PRED6DOF_HEADER + "\n1, 0, 0, 0, 0, 0, 0, 0\n"))


def test_load_trace_detects_format_and_names_builtins(tmp_path):
    canonical = tmp_path / "c.csv"
    write_canonical_csv(random_trace(5), canonical)
    assert len(load_trace(canonical)) == 5
    pred = write(tmp_path / "p.csv", PRED6DOF_HEADER + "\n10000, 0, 0, 1, 0, 0, 0, 1\n20000, 0, 0, 2, 0, 0, 0, 1\n")
    trace = load_trace(str(pred))
    np.testing.assert_allclose(trace.positions[:, 2], [-1.0, -2.0])
    with pytest.raises(TraceError, match="unrecognised trace header"):
        load_trace(write(tmp_path / "o.csv", "a,b,c\n1,2,3\n"))
    with pytest.raises(TraceError, match="pred6dof-1, pred6dof-2"):
        load_trace("no-such-trace")


# --------------------------------------------------------------------------------- plain CSV


def test_import_csv_euler_degrees_with_header(tmp_path):
    path = write(tmp_path / "e.csv", "# exported by a tool\nms;X;Y;Z;heading;elev;bank\n"
                                     "1000;0;1.6;0;0;0;0\n1010;0;1.6;-1;90;0;0\n1020;0;1.6;-2;0;30;0\n")
    trace = import_csv(path, {"t": "ms", "px": "X", "py": "Y", "pz": "Z", "yaw": "heading",
                              "pitch": "elev", "roll": "bank"},
                       time_unit="ms", rotation="euler", delimiter=";", skip_rows=1)
    np.testing.assert_allclose(trace.t, [0.0, 0.01, 0.02])
    np.testing.assert_allclose(trace.positions[1], [0, 1.6, -1])
    np.testing.assert_allclose(trace.pose_at(0.01).forward(), [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(trace.pose_at(0.02).forward()[1], math.sin(math.radians(30)))


def test_import_csv_quaternion_xyzw_by_index_left_handed(tmp_path):
    rng = np.random.default_rng(3)
    unity_p = rng.normal(size=(4, 3))
    unity_q = quat_normalize(rng.normal(size=(4, 4)))  # (w, x, y, z)
    ns = 1_700_000_000_000_000_000 + np.arange(4) * 1_000_000  # epoch ns, 1 ms apart
    lines = [f"{s} {p[0]!r} {p[1]!r} {p[2]!r}  {q[1]!r} {q[2]!r} {q[3]!r} {q[0]!r}"
             for s, p, q in zip(ns.tolist(), unity_p.tolist(), unity_q.tolist())]
    path = write(tmp_path / "raw.txt", "\n".join(lines) + "\n")
    trace = import_csv(path, {"t": 0, "p": 1, "q": 4}, time_unit="ns", quat_order="xyzw",
                       handedness="left", delimiter=None)
    np.testing.assert_array_equal(trace.t, np.arange(4) * 1e-3)  # exact despite 1.7e18 ns stamps
    expect_p, expect_q = left_handed_to_right_handed(unity_p, unity_q)
    np.testing.assert_allclose(trace.positions, expect_p)
    np.testing.assert_allclose(trace.orientations, quat_normalize(expect_q), atol=1e-12)


def test_import_csv_matches_pred6dof_importer():
    path = builtin_file("2.csv")
    columns = parse_columns("t=timestamp,px=x,py=y,pz=z,qw=qw,qx=qx,qy=qy,qz=qz")
    generic = import_csv(path, columns, time_unit="ticks", handedness="left")
    special = import_pred6dof(path)
    np.testing.assert_array_equal(generic.t, special.t)
    np.testing.assert_array_equal(generic.positions, special.positions)
    np.testing.assert_allclose(generic.orientations, special.orientations, atol=1e-15)


def test_import_csv_errors(tmp_path):
    path = write(tmp_path / "x.csv", "time,x,y,z,w,i,j,k\n0,0,0,0,1,0,0,0\n1,0,0,oops,1,0,0,0\n2,0,0,0,1,0\n")
    full = {"t": "time", "px": "x", "py": "y", "pz": "z", "qw": "w", "qx": "i", "qy": "j", "qz": "k"}
    with pytest.raises(TraceError, match="line 3: column 'z': 'oops' is not a number"):
        import_csv(path, full)
    with pytest.raises(TraceError, match=r"'stamp' \(for t\) is not in the header; available: time, x, y"):
        import_csv(path, {**full, "t": "stamp"})
    with pytest.raises(TraceError, match="missing column mapping for qw, qx, qy, qz"):
        import_csv(path, {"t": "time", "px": "x", "py": "y", "pz": "z"})
    with pytest.raises(TraceError, match="unknown column key"):
        import_csv(path, {**full, "speed": "x"})
    path = write(tmp_path / "y.csv", "time,x,y,z,w,i,j,k\n0,0,0,0,1,0,0,0\n1,0,0,0,1,0\n")
    with pytest.raises(TraceError, match="line 3: has 6 columns, the header has 8"):
        import_csv(path, full)
    path = write(tmp_path / "d.csv", "time,x,y,z,w,i,j,k\n0,0,0,0,1,0,0,0\n0,1,0,0,1,0,0,0\n")
    with pytest.raises(TraceError, match="line 3: duplicate timestamp"):
        import_csv(path, full)
    assert len(import_csv(path, full, duplicates="drop")) == 1


# --------------------------------------------------------------------------------- synthesis


def test_synthesize_is_deterministic():
    a = synthesize("mixed", 20.0, rate_hz=60, seed=7)
    b = synthesize("mixed", 20.0, rate_hz=60, seed=7)
    c = synthesize("mixed", 20.0, rate_hz=60, seed=8)
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.orientations, b.orientations)
    assert not np.array_equal(a.orientations, c.orientations)


@pytest.mark.parametrize("kind", ["walk", "look", "turns", "mixed"])
def test_synthesize_starts_at_origin_uniform_and_smooth(kind):
    trace = synthesize(kind, 30.0, rate_hz=60, seed=1, eye_height=1.6)
    assert len(trace) == 30 * 60 + 1
    np.testing.assert_allclose(np.diff(trace.t), 1 / 60)
    np.testing.assert_allclose(trace.positions[0], [0, 1.6, 0], atol=1e-12)
    np.testing.assert_allclose(trace.orientations[0], [1, 0, 0, 0], atol=1e-12)
    # C1: velocities change by small steps from one interval to the next, never jump.
    velocity = np.diff(trace.positions, axis=0) * 60
    assert np.abs(np.diff(velocity, axis=0)).max() < 0.06
    linear, angular = trace.speeds()
    assert np.abs(np.diff(angular)).max() < 0.15 * angular.max()


def test_synthesize_respects_speeds():
    walk_linear, walk_angular = synthesize("walk", 40.0, rate_hz=60, seed=2, walk_speed=1.4,
                                           turn_speed_deg=80).speeds()
    assert 1.4 <= walk_linear.max() <= 1.4 * 1.03  # bob and sway add a little
    assert np.median(walk_linear) == pytest.approx(1.4, rel=0.02)
    assert np.degrees(walk_angular.max()) <= 80 * 1.01

    _, look = synthesize("look", 20.0, rate_hz=120, seed=3, turn_speed_deg=45).speeds()
    assert np.degrees(look.max()) == pytest.approx(45, rel=0.01)
    look_linear, turns = synthesize("turns", 20.0, rate_hz=120, seed=3, quick_turn_deg_s=300).speeds()
    assert np.degrees(turns.max()) == pytest.approx(300, rel=0.01)
    assert look_linear.max() < 0.05  # standing still but for sway

    mixed_linear, mixed_angular = synthesize("mixed", 40.0, rate_hz=60, seed=4).speeds()
    assert mixed_linear.max() == pytest.approx(1.0, rel=0.03)
    assert np.degrees(mixed_angular.max()) == pytest.approx(250, rel=0.01)


def test_synthesize_rejects_bad_parameters():
    with pytest.raises(ConfigError, match="unknown synthetic trace kind"):
        synthesize("run", 10)
    with pytest.raises(ConfigError, match="rate_hz"):
        synthesize("walk", 10, rate_hz=0)


# --------------------------------------------------------------------------------- CLI


def run_registered(argv) -> int:
    from pibr import trace_cli

    parser = argparse.ArgumentParser(prog="pibr")
    trace_cli.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    return args.func(args)


def test_cli_convert_builtin_with_rate(tmp_path, capsys):
    out = tmp_path / "out.csv"
    assert run_registered(["trace", "convert", "pred6dof-1", str(out), "--rate", "90", "--duration", "10"]) == 0
    trace = read_canonical_csv(out)
    assert len(trace) == 901
    np.testing.assert_array_equal(trace.t, np.arange(901) / 90)
    assert "901 samples" in capsys.readouterr().out


def test_cli_convert_csv_columns_and_slice(tmp_path):
    src = write(tmp_path / "in.csv", "time,x,y,z,w,i,j,k\n0,0,0,0,1,0,0,0\n500,1,0,0,1,0,0,0\n1000,2,0,0,1,0,0,0\n")
    out = tmp_path / "out.csv"
    argv = ["trace", "convert", str(src), str(out), "--columns", "t=time,px=x,py=y,pz=z,qw=w,qx=i,qy=j,qz=k",
            "--time-unit", "ms", "--start", "0.25"]
    assert run_registered(argv) == 0
    trace = read_canonical_csv(out)
    np.testing.assert_allclose(trace.t, [0.0, 0.25, 0.75])
    np.testing.assert_allclose(trace.positions[:, 0], [0.5, 1.0, 2.0])
    with pytest.raises(TraceError, match="--time-unit applies to pred6dof and csv input, not to a built-in"):
        run_registered(["trace", "convert", "pred6dof-1", str(out), "--time-unit", "ms"])


def test_cli_show_synth_list(tmp_path, capsys):
    synth = tmp_path / "s.csv"
    assert run_registered(["trace", "synth", str(synth), "--kind", "look", "--duration", "5",
                           "--rate", "50", "--seed", "3", "--turn-speed", "40"]) == 0
    assert len(read_canonical_csv(synth)) == 251
    capsys.readouterr()

    assert run_registered(["trace", "show", str(synth), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["samples"] == 251
    assert info["angular_speed_deg_s"]["max"] == pytest.approx(40, rel=0.02)

    png = tmp_path / "p.png"
    assert run_registered(["trace", "show", "pred6dof-2", "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert "samples" in text and "4343" in text and "deg/s" in text
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    assert run_registered(["trace", "list"]) == 0
    assert "pred6dof-1" in capsys.readouterr().out


def test_cli_through_pibr_main(tmp_path, capsys):
    try:
        from pibr.cli import build_parser, main

        build_parser()
    except ImportError as exc:  # another command module is not written yet
        pytest.skip(f"pibr.cli cannot load every command module yet: {exc}")
    out = tmp_path / "w.csv"
    assert main(["trace", "synth", str(out), "--kind", "walk", "--duration", "3", "--rate", "30"]) == 0
    assert len(read_canonical_csv(out)) == 91
    assert main(["trace", "list"]) == 0
    capsys.readouterr()
    bad = write(tmp_path / "bad.csv", CANONICAL_HEADER + "\n0,0,0,0,1,0,0,0\n0.1,0,0,0,0,0,0,0\n")
    assert main(["trace", "show", str(bad)]) == 2
    assert "line 3: zero quaternion" in capsys.readouterr().err
