"""Head traces as users bring them: each shape of recording that once needed hand-written
Python, in a small file of the same shape made here, imported with one documented command."""
from __future__ import annotations

import math

import numpy as np
import pytest

from pibr.protocol.errors import TraceError
from pibr.protocol.pose import Pose, quat_from_axis_angle, quat_rotate
from pibr.common.traces.canonical import read_canonical_csv
from pibr.common.traces.loading import detect_format, load_trace
from pibr.common.traces.importers import axis_conversion, convert_axes, import_csv, import_pred6dof, parse_columns


def write(path, text: str):
    path.write_text(text)
    return path


def forward(q) -> np.ndarray:
    """Where a pibr head with orientation q looks (its -Z)."""
    return quat_rotate(q, [0.0, 0.0, -1.0])


def run_cli(argv):
    from pibr.cli import main

    return main(argv)


# ------------------------------------------------------------------------------ axes


@pytest.mark.parametrize("handedness, up, fwd, right", [
    ("right", "y", "-z", (1, 0, 0)), ("left", "y", "z", (1, 0, 0)),
    ("right", "z", "y", (1, 0, 0)), ("right", "z", "x", (0, -1, 0)),
])
def test_axis_conversion_maps_forward_up_and_right(handedness, up, fwd, right):
    m = axis_conversion(handedness, up, fwd)
    axis = {"x": [1, 0, 0], "y": [0, 1, 0], "z": [0, 0, 1], "-z": [0, 0, -1]}
    np.testing.assert_allclose(m @ axis[up], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(m @ axis[fwd], [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(m @ np.array(right, float), [1, 0, 0], atol=1e-12)


def test_unity_conversion_matches_the_mirror_of_z():
    """The general conversion reproduces the pred6dof importer's left-handed mirror exactly."""
    rng = np.random.default_rng(1)
    p, q = rng.normal(size=(20, 3)), rng.normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    p2, q2 = convert_axes(p, q, axis_conversion("left", "y", "z"))
    np.testing.assert_allclose(p2, p * [1, 1, -1], atol=1e-12)
    same = np.minimum(np.abs(q2 - q * [1, -1, -1, 1]).max(axis=1), np.abs(q2 + q * [1, -1, -1, 1]).max(axis=1))
    assert same.max() < 1e-12


def test_bad_axes_are_named():
    with pytest.raises(TraceError, match="perpendicular"):
        axis_conversion("right", "z", "-z")
    with pytest.raises(TraceError, match="unknown axis 'w'"):
        axis_conversion("right", "y", "w")


# ------------------------------------------------------------------------------ 1. HoloLens 2 with extra columns


HL2 = ("timestamp,x,y,z,qx,qy,qz,qw,vx,vy,vz,speed\n"
       "638000000000000000,0.1,1.5,0.2,0,0,0,1,0,0,0,0\n"
       "638000000000166667,0.1,1.5,0.3,0,0.0871557,0,0.9961947,0,0,6,6\n")


def test_hololens2_log_with_velocity_columns_imports_as_pred6dof(tmp_path):
    path = write(tmp_path / "hl2.csv", HL2)
    assert detect_format(path) == "pred6dof"
    trace = import_pred6dof(path)
    assert len(trace) == 2 and trace.t[1] == pytest.approx(0.0166667)
    np.testing.assert_allclose(trace.positions[1], [0.1, 1.5, -0.3])       # Unity +Z forward -> pibr -Z
    assert trace.assumptions["ignored columns"] == "vx, vy, vz, speed"
    assert "left-handed" in trace.assumptions["axes"] and "converted" in trace.assumptions["axes"]
    assert load_trace(path).assumptions == trace.assumptions                  # found by its header alone


# ------------------------------------------------------------------------------ 2. Quest 2: mixed delimiters, Euler


def test_quest_log_with_whitespace_header_over_comma_rows(tmp_path):
    """Header 'Time x y z alpha beta gamma' split on spaces, rows on commas; angles about Z, X,
    Y applied in that order (intrinsic zxy), in a Y-up right-handed world."""
    path = write(tmp_path / "quest.txt", "Time x y z alpha beta gamma\n"
                                         "0.000,0.0,1.6,0.0,0,0,0\n"
                                         "0.020,0.0,1.6,0.0,0,0,90\n"
                                         "0.040,0.0,1.6,0.0,90,0,0\n")
    trace = import_csv(path, parse_columns("t=Time,px=x,py=y,pz=z,rz=alpha,rx=beta,ry=gamma"), rotation="euler",
                       euler_order="zxy")
    assert len(trace) == 3
    np.testing.assert_allclose(forward(trace.orientations[0]), [0, 0, -1], atol=1e-9)
    np.testing.assert_allclose(forward(trace.orientations[1]), [-1, 0, 0], atol=1e-9)   # 90 deg about +Y: left
    np.testing.assert_allclose(forward(trace.orientations[2]), [0, 0, -1], atol=1e-9)   # roll keeps the view axis
    assert trace.assumptions["delimiter"] == "whitespace (header), comma (rows)"
    assert "intrinsically in the order z (alpha) then x (beta) then y (gamma)" in trace.assumptions["rotation"]


def test_a_mismatched_explicit_delimiter_says_how_to_fix_it(tmp_path):
    path = write(tmp_path / "quest.txt", "Time x y z alpha beta gamma\n0.0,0,1.6,0,0,0,0\n")
    with pytest.raises(TraceError, match="line 2: has 1 columns, the header has 7.*--delimiter auto"):
        import_csv(path, parse_columns("t=Time,px=x,py=y,pz=z,rz=alpha,rx=beta,ry=gamma"), rotation="euler",
                   euler_order="zxy", delimiter=None)


# ------------------------------------------------------------------------------ 3. absolute game-world positions


def test_recentre_moves_the_first_pose_to_the_origin_and_optionally_its_heading(tmp_path):
    turned = quat_from_axis_angle([0, 1, 0], math.radians(30))
    rows = [f"{t},{24 + t},1.7,{-3 - t},{turned[0]},{turned[1]},{turned[2]},{turned[3]}" for t in range(3)]
    path = write(tmp_path / "level.csv", "t,x,y,z,qw,qx,qy,qz\n" + "\n".join(rows) + "\n")
    columns = parse_columns("t=t,px=x,py=y,pz=z,qw=qw,qx=qx,qy=qy,qz=qz")
    plain = import_csv(path, columns, recentre="position")
    np.testing.assert_allclose(plain.positions[0], 0, atol=1e-12)
    np.testing.assert_allclose(plain.positions[2], [2, 0, -2], atol=1e-12)
    yawed = import_csv(path, columns, recentre="yaw")
    np.testing.assert_allclose(forward(yawed.orientations[0]), [0, 0, -1], atol=1e-9)
    # the path turned with it: it went forward-right at 45 deg, minus the 30 deg heading
    step = yawed.positions[1] - yawed.positions[0]
    assert math.degrees(math.atan2(step[0], -step[2])) == pytest.approx(45 + 30)
    assert "turned -30.0 deg" in yawed.assumptions["recentred"]


def test_cli_recentre_works_for_any_format(tmp_path, capsys):
    path = write(tmp_path / "hl2.csv", HL2)
    out = tmp_path / "out.csv"
    assert run_cli(["trace", "convert", str(path), str(out), "--recentre"]) == 0
    np.testing.assert_allclose(read_canonical_csv(out).positions[0], 0, atol=1e-12)


@pytest.mark.parametrize("cut", [["--start", "1.5"], ["--start", "1.5", "--rate", "10"]])
def test_cli_recentre_after_a_cut_centres_the_first_kept_sample(tmp_path, cut):
    """Issue 26 (8): with --start, the first sample written is at the origin (it was the
    recording's first sample, so the cut trace began 1.5 m away), and yaw turns its heading."""
    turned = quat_from_axis_angle([0, 1, 0], math.radians(40))
    rows = [f"{0.5 * k},{k},1.6,{-2 * k},{turned[0]},{turned[1]},{turned[2]},{turned[3]}" for k in range(8)]
    path = write(tmp_path / "walk.csv", "t,px,py,pz,qw,qx,qy,qz\n" + "\n".join(rows) + "\n")
    out = tmp_path / "out.csv"
    assert run_cli(["trace", "convert", str(path), str(out), "--recentre", "yaw"] + cut) == 0
    trace = read_canonical_csv(out)
    np.testing.assert_allclose(trace.positions[0], 0, atol=1e-9)
    np.testing.assert_allclose(forward(trace.orientations[0]), [0, 0, -1], atol=1e-9)
    assert trace.duration == pytest.approx(2.0)
    # the head still walks 1 m along x and 2 m along -z per half second, turned with the heading
    assert np.linalg.norm(trace.positions[-1]) == pytest.approx(math.hypot(4, 8), rel=1e-6)


# ------------------------------------------------------------------------------ 4. orientation only, Z up


def test_orientation_only_z_up_trace_from_a_360_video_study(tmp_path):
    """'timestamp viewpoint w x y z' (whitespace), quaternions in a Z-up world whose identity
    looks along +Y: no positions, so the head stays at the origin, or moves on a neck model."""
    left = quat_from_axis_angle([0, 0, 1], math.radians(90))            # turn left about Z-up
    up = quat_from_axis_angle([1, 0, 0], math.radians(30))              # look up about the right axis
    rows = [f"{0.1 * i:.1f} {i} " + " ".join(map(str, q)) for i, q in enumerate(([1, 0, 0, 0], left, up))]
    path = write(tmp_path / "video.txt", "timestamp viewpoint w x y z\n" + "\n".join(rows) + "\n")
    columns = parse_columns("t=timestamp,qw=w,qx=x,qy=y,qz=z")
    with pytest.raises(TraceError, match="--positions fixed.*--positions neck"):
        import_csv(path, columns, up="z")
    fixed = import_csv(path, columns, up="z", positions="fixed")
    np.testing.assert_allclose(fixed.positions, 0)
    np.testing.assert_allclose(forward(fixed.orientations[0]), [0, 0, -1], atol=1e-9)
    np.testing.assert_allclose(forward(fixed.orientations[1]), [-1, 0, 0], atol=1e-9)
    np.testing.assert_allclose(forward(fixed.orientations[2]), [0, math.sin(math.radians(30)),
                                                                -math.cos(math.radians(30))], atol=1e-9)
    assert fixed.assumptions["ignored columns"] == "viewpoint"
    assert "orientation only" in fixed.assumptions["positions"]
    neck = import_csv(path, columns, up="z", positions="neck")
    np.testing.assert_allclose(neck.positions[0], 0, atol=1e-12)
    # turning the head swings the eyes around the pivot: 8 cm forward becomes 8 cm to the left
    np.testing.assert_allclose(neck.positions[1], [-0.08, 0, 0.08], atol=1e-9)
    assert "head-neck model" in neck.assumptions["positions"]


def test_positions_mode_and_position_columns_must_agree(tmp_path):
    path = write(tmp_path / "a.csv", "t,x,y,z,qw,qx,qy,qz\n0,0,0,0,1,0,0,0\n")
    with pytest.raises(TraceError, match="--positions fixed is for traces without positions"):
        import_csv(path, parse_columns("t=t,px=x,py=y,pz=z,qw=qw,qx=qx,qy=qy,qz=qz"), positions="fixed")


# ------------------------------------------------------------------------------ trace show


def test_trace_show_prints_what_was_assumed(tmp_path, capsys):
    path = write(tmp_path / "hl2.csv", HL2)
    assert run_cli(["trace", "show", str(path)]) == 0
    out = capsys.readouterr().out
    for fragment in ("assumed format", "pred6dof", "assumed time", ".NET ticks", "assumed axes", "left-handed",
                     "assumed ignored columns", "vx, vy, vz, speed", "rate"):
        assert fragment in out, fragment
    video = write(tmp_path / "video.txt", "timestamp viewpoint w x y z\n0 1 1 0 0 0\n0.1 1 1 0 0 0\n")
    assert run_cli(["trace", "show", str(video), "--columns", "t=timestamp,qw=w,qx=x,qy=y,qz=z", "--up", "z",
                    "--positions", "neck"]) == 0
    out = capsys.readouterr().out
    assert "+z up" in out and "head-neck model" in out


# ------------------------------------------------------------------------------ 5. placing the window


def test_a_late_window_starts_at_the_viewer_origin_facing_its_way():
    from pibr.common.traces.placement import heading, placement

    trace = load_trace("pred6dof-1")
    origin = Pose.make([2.0, 1.6, -1.0], quat_from_axis_angle([0, 1, 0], math.radians(40)))
    for start in (0.0, 30.0, 70.0):
        place = placement(trace, start, origin)
        first = place.compose(trace.pose_at(start))
        np.testing.assert_allclose(first.p, origin.p, atol=1e-9)
        assert heading(first.q) == pytest.approx(math.radians(40), abs=1e-9)
        # the head's pitch is kept: the angle of its view axis above the floor
        raw = forward(trace.pose_at(start).q)
        placed = forward(first.q)
        assert math.asin(placed[1]) == pytest.approx(math.asin(raw[1]), abs=1e-9)
        # the motion is rigid: distances along the window are the trace's
        later = place.compose(trace.pose_at(start + 2.0))
        assert np.linalg.norm(later.p - first.p) == pytest.approx(
            np.linalg.norm(trace.pose_at(start + 2.0).p - trace.pose_at(start).p))
    assert placement(trace, 30.0, origin, "origin") == origin
    assert placement(trace, 30.0, origin, "none") == Pose.identity()
    with pytest.raises(TraceError, match="unknown anchor"):
        placement(trace, 30.0, origin, "middle")


# ---------------------------------------------------------------- issue 13, defect 15: numbers a trace file controls

PRED_HEADER = "timestamp,x,y,z,qx,qy,qz,qw\n"


@pytest.mark.parametrize("stamp", [str(2**63), str(-2**63 - 1), "9" * 401])
def test_pred6dof_timestamps_past_64_bits_are_trace_errors(tmp_path, stamp):
    path = write(tmp_path / "p.csv", PRED_HEADER + "0,0,0,0,0,0,0,1\n" + stamp + ",0,0,0,0,0,0,1\n")
    with pytest.raises(TraceError, match=r"line 3: column 't': integer timestamp .* does not fit 64 bits"):
        import_pred6dof(path)


def test_csv_timestamps_past_64_bits_are_trace_errors(tmp_path):
    path = write(tmp_path / "c.csv", "t,px,py,pz,qw,qx,qy,qz\n0,0,0,0,1,0,0,0\n" + "9" * 401 + ",0,0,0,1,0,0,0\n")
    with pytest.raises(TraceError, match="line 3: column 't': integer timestamp '999"):
        import_csv(path, {"t": "t", "p": 1, "q": 4})
    path = write(tmp_path / "d.csv", "t,px,py,pz,qw,qx,qy,qz\n0,0,0,0,1,0,0,0\n" + "9" * 5000 + ",0,0,0,1,0,0,0\n")
    with pytest.raises(TraceError, match="line 3: column 't' is infinite"):
        import_csv(path, {"t": "t", "p": 1, "q": 4})


def test_largest_64_bit_ticks_still_import(tmp_path):
    start = 2**63 - 1 - 10_000_000
    path = write(tmp_path / "p.csv", PRED_HEADER + f"{start},0,0,0,0,0,0,1\n{2**63 - 1},0,0,0,0,0,0,1\n")
    assert import_pred6dof(path).duration == pytest.approx(1.0)


@pytest.mark.parametrize("text, match", [
    ("t=" + "1" * 5000, "a column index is at most 100000"),
    ("t=100001", "a column index is at most 100000"),
])
def test_column_indices_are_bounded(text, match):
    with pytest.raises(TraceError, match=match):
        parse_columns(text)


def test_unicode_digits_are_header_names_not_indices():
    assert parse_columns("t=²,px=٣") == {"t": "²", "px": "٣"}   # str.isdigit() is true, int() refuses them
    assert parse_columns("t=12") == {"t": 12}


def test_columns_option_with_a_huge_index_is_a_trace_error_on_the_command_line(tmp_path, capsys):
    path = write(tmp_path / "c.csv", "0 0 0 0 1 0 0 0\n1 0 0 0 1 0 0 0\n")
    assert run_cli(["trace", "show", str(path), "--columns", "t=" + "1" * 5000 + ",p=1,q=4"]) == 2
    assert "a column index is at most" in capsys.readouterr().err


def test_span_positions_and_resampling_are_bounded(tmp_path):
    from pibr.protocol.trace import HeadTrace, MAX_DURATION_S, MAX_POSITION_M, MAX_SAMPLES

    ticks = int(MAX_DURATION_S * 1e7) + 10
    path = write(tmp_path / "p.csv", PRED_HEADER + f"0,0,0,0,0,0,0,1\n{ticks},0,0,0,0,0,0,1\n")
    with pytest.raises(TraceError, match="more than the limit of .* s .are the timestamps in the unit assumed"):
        import_pred6dof(path)
    path = write(tmp_path / "c.csv", f"t,px,py,pz,qw,qx,qy,qz\n0,0,0,{MAX_POSITION_M * 2},1,0,0,0\n")
    with pytest.raises(TraceError, match="farther than"):
        load_trace(path)
    trace = HeadTrace(np.array([0.0, 1000.0]), np.zeros((2, 3)), np.tile([1.0, 0, 0, 0], (2, 1)))
    with pytest.raises(TraceError, match=f"more than the limit of {MAX_SAMPLES}"):
        trace.resample(1e5)
    assert len(trace.resample(10.0)) == 10_001


def test_huge_quaternion_components_normalise(tmp_path):
    path = write(tmp_path / "c.csv", "t,px,py,pz,qw,qx,qy,qz\n0,0,0,0,1e300,0,1e300,0\n1,0,0,0,1,0,0,0\n")
    trace = load_trace(path)
    assert trace.orientations[0] == pytest.approx([math.sqrt(0.5), 0, math.sqrt(0.5), 0])
