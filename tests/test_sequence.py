"""Frame patterns, ranges, input expansion, output naming and shards (ranad_core.exr.sequence)."""

from __future__ import annotations

import os

import pytest

from ranad_core.errors import RanadError
from ranad_core.exr.sequence import (
    Frame,
    expand_inputs,
    format_frame,
    is_pattern,
    output_path,
    output_paths,
    parse_frame_range,
    shard,
)


def touch(folder, *names):
    for name in names:
        (folder / name).write_bytes(b"x")


# --- patterns -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "s, expected",
    [
        ("shot.####.exr", True),
        ("shot.#.exr", True),
        ("shot.%04d.exr", True),
        ("shot.%d.exr", True),
        ("shot.@@@@.exr", True),
        ("shot.1001.exr", False),
        ("shot.exr", False),
        ("render#1/shot.exr", False),  # a '#' in a folder name is not a placeholder
        ("100%.exr", False),
    ],
)
def test_is_pattern(s, expected):
    assert is_pattern(s) is expected


@pytest.mark.parametrize(
    "pattern, frame, expected",
    [
        ("shot.####.exr", 7, "shot.0007.exr"),
        ("shot.####.exr", 1001, "shot.1001.exr"),
        ("shot.####.exr", 123456, "shot.123456.exr"),  # wider than the pad: written in full
        ("shot.#.exr", 1001, "shot.1001.exr"),
        ("shot.%04d.exr", 42, "shot.0042.exr"),
        ("shot.%d.exr", 42, "shot.42.exr"),
        ("shot.%06d.exr", 42, "shot.000042.exr"),
        ("shot.@@@@.exr", 5, "shot.0005.exr"),
        ("shot.@@.exr", 5, "shot.05.exr"),
        ("shot.####.exr", -5, "shot.-005.exr"),  # printf semantics: the sign counts toward the width
        ("dir#1/shot_####_beauty.exr", 3, "dir#1/shot_0003_beauty.exr"),
    ],
)
def test_format_frame(pattern, frame, expected):
    assert format_frame(pattern, frame) == expected


def test_format_frame_rejects_plain_and_ambiguous_names():
    with pytest.raises(RanadError):
        format_frame("shot.exr", 1)
    with pytest.raises(RanadError) as e:
        format_frame("shot.####.v##.exr", 1)
    assert "more than one" in str(e.value)


# --- frame ranges -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "s, expected",
    [
        ("1001-1005", [1001, 1002, 1003, 1004, 1005]),
        ("1001", [1001]),
        ("1001-1010x2", [1001, 1003, 1005, 1007, 1009]),
        ("1001-1100x25", [1001, 1026, 1051, 1076]),
        ("1001-1003,1010", [1001, 1002, 1003, 1010]),
        ("1-3, 2, 7-9x2", [1, 2, 3, 7, 9]),
        ("-2-1", [-2, -1, 0, 1]),
        ("-5--3", [-5, -4, -3]),
        ("-7", [-7]),
        ("5-5", [5]),
    ],
)
def test_parse_frame_range(s, expected):
    assert parse_frame_range(s) == expected


@pytest.mark.parametrize("bad", ["", "  ", "abc", "1001-", "1001-1010x", "1001-1010x0", "1010-1001", "1,,2", "1-2-3", "1.5"])
def test_parse_frame_range_errors_name_the_string(bad):
    with pytest.raises(RanadError) as e:
        parse_frame_range(bad)
    assert repr(bad) in str(e.value)


def test_parse_frame_range_refuses_a_billion_frames():
    """3-999999999 built a list of a billion frame numbers (tens of GB) before any file was looked at."""
    with pytest.raises(RanadError, match="names more than 1000000 frames"):
        parse_frame_range("3-999999999")
    with pytest.raises(RanadError, match="more than"):
        parse_frame_range("1-600000,700000-1300000")
    assert len(parse_frame_range("1-1000000")) == 1000000


# --- expand_inputs ------------------------------------------------------------------------------


@pytest.mark.parametrize("pattern", ["shot.####.exr", "shot.%04d.exr", "shot.@@@@.exr"])
def test_expand_pattern_with_frames(tmp_path, pattern):
    touch(tmp_path, *(f"shot.{n:04d}.exr" for n in range(1001, 1011)))
    got = expand_inputs([str(tmp_path / pattern)], frames="1001-1009x4")
    assert got == [Frame(str(tmp_path / f"shot.{n}.exr"), n) for n in (1001, 1005, 1009)]


def test_expand_missing_frame_names_it(tmp_path):
    touch(tmp_path, "shot.1001.exr", "shot.1002.exr", "shot.1004.exr")
    with pytest.raises(RanadError) as e:
        expand_inputs([str(tmp_path / "shot.####.exr")], frames="1001-1004")
    assert e.value.problem == "frame 1003 is missing"
    assert e.value.path == str(tmp_path / "shot.1003.exr")


@pytest.mark.parametrize("pattern", ["shot.####.exr", "shot.%04d.exr", "shot.@@@@.exr"])
def test_expand_scans_disk_sorted(tmp_path, pattern):
    touch(tmp_path, "shot.1003.exr", "shot.1001.exr", "shot.1002.exr")
    # Look-alikes that are not frames of this pattern.
    touch(tmp_path, "shot.1001.exr.tmp", "other.1001.exr", "shot.100.exr", "shot.01004.exr", "shot.abcd.exr")
    (tmp_path / "shot.1004.exr").mkdir()  # a folder is not a frame
    got = expand_inputs([str(tmp_path / pattern)])
    assert got == [Frame(str(tmp_path / f"shot.{n}.exr"), n) for n in (1001, 1002, 1003)]


def test_expand_scan_accepts_numbers_wider_than_pad(tmp_path):
    touch(tmp_path, "a.9.exr", "a.10.exr", "a.11.exr", "b.0010.exr")
    got = expand_inputs([str(tmp_path / "a.#.exr")])
    assert [f.frame for f in got] == [9, 10, 11]
    got = expand_inputs([str(tmp_path / "a.%d.exr")])
    assert [f.frame for f in got] == [9, 10, 11]
    # "b.0010.exr" is frame 10 of b.####.exr, not of b.#.exr (whose frame 10 is "b.10.exr").
    with pytest.raises(RanadError):
        expand_inputs([str(tmp_path / "b.#.exr")])
    assert [f.frame for f in expand_inputs([str(tmp_path / "b.####.exr")])] == [10]


def test_expand_scan_negative_frames(tmp_path):
    touch(tmp_path, "n.-002.exr", "n.-001.exr", "n.0000.exr", "n.0001.exr")
    got = expand_inputs([str(tmp_path / "n.####.exr")])
    assert [f.frame for f in got] == [-2, -1, 0, 1]


def test_expand_relative_pattern_in_cwd(tmp_path, monkeypatch):
    touch(tmp_path, "s.0001.exr", "s.0002.exr")
    monkeypatch.chdir(tmp_path)
    assert expand_inputs(["s.####.exr"]) == [Frame("s.0001.exr", 1), Frame("s.0002.exr", 2)]


def test_expand_no_match(tmp_path):
    touch(tmp_path, "other.0001.exr")
    spec = str(tmp_path / "shot.####.exr")
    with pytest.raises(RanadError) as e:
        expand_inputs([spec])
    assert e.value.problem == "no frames match this pattern"
    assert e.value.path == spec


def test_expand_missing_folder(tmp_path):
    with pytest.raises(RanadError):
        expand_inputs([str(tmp_path / "nope" / "shot.####.exr")])


def test_expand_gaps(tmp_path):
    touch(tmp_path, "shot.1001.exr", "shot.1002.exr", "shot.1005.exr", "shot.1007.exr")
    spec = str(tmp_path / "shot.####.exr")
    with pytest.raises(RanadError) as e:
        expand_inputs([spec])
    assert "frame 1003 is missing" in e.value.problem
    assert e.value.path == str(tmp_path / "shot.1003.exr")
    got = expand_inputs([spec], allow_gaps=True)
    assert [f.frame for f in got] == [1001, 1002, 1005, 1007]


def test_expand_plain_files_and_duplicates(tmp_path, monkeypatch):
    touch(tmp_path, "a.exr", "b.exr", "shot.0001.exr", "shot.0002.exr")
    a, b = str(tmp_path / "a.exr"), str(tmp_path / "b.exr")
    monkeypatch.chdir(tmp_path)
    got = expand_inputs([b, a, "b.exr", "shot.####.exr", str(tmp_path / "shot.0002.exr"), a])
    assert got == [Frame(b, None), Frame(a, None), Frame("shot.0001.exr", 1), Frame("shot.0002.exr", 2)]


def test_expand_plain_file_missing(tmp_path):
    path = str(tmp_path / "nope.exr")
    with pytest.raises(RanadError) as e:
        expand_inputs([path])
    assert e.value.problem == "no such file"
    assert e.value.path == path


def test_expand_frames_do_not_apply_to_plain_files(tmp_path):
    touch(tmp_path, "a.exr", "s.0003.exr")
    got = expand_inputs([str(tmp_path / "a.exr"), str(tmp_path / "s.####.exr")], frames="3")
    assert got == [Frame(str(tmp_path / "a.exr"), None), Frame(str(tmp_path / "s.0003.exr"), 3)]


def test_expand_bad_frames_string(tmp_path):
    touch(tmp_path, "s.0003.exr")
    with pytest.raises(RanadError) as e:
        expand_inputs([str(tmp_path / "s.####.exr")], frames="3..5")
    assert "'3..5'" in str(e.value)


# --- output_path --------------------------------------------------------------------------------


def test_output_path_pattern(tmp_path):
    out = str(tmp_path / "den.%05d.exr")
    assert output_path(out, Frame("in.1001.exr", 1001), 10) == str(tmp_path / "den.01001.exr")
    assert output_path("den.@@@@.png", Frame("x", 7), 1) == "den.0007.png"


def test_output_path_pattern_needs_frame_number(tmp_path):
    with pytest.raises(RanadError) as e:
        output_path("den.####.exr", Frame("in.exr", None), 1)
    assert e.value.path == "in.exr"
    assert "den.####.exr" in e.value.problem


def test_output_path_folder(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    f = Frame(str(tmp_path / "src" / "shot.1001.exr"), 1001)
    assert output_path(str(out), f, 5) == str(out / "shot.1001.exr")
    assert output_path(str(out), f, 5, ext=".png") == str(out / "shot.1001.png")
    assert output_path(str(out), f, 5, ext="jpg") == str(out / "shot.1001.jpg")
    assert output_path(str(out) + os.sep, f, 1) == str(out / "shot.1001.exr")


def test_output_path_folder_missing(tmp_path):
    with pytest.raises(RanadError) as e:
        output_path(str(tmp_path / "nope") + os.sep, Frame("a.exr"), 1)
    assert "does not exist" in e.value.problem


def test_output_path_folder_refuses_overwriting_input(tmp_path):
    touch(tmp_path, "shot.exr")
    with pytest.raises(RanadError) as e:
        output_path(str(tmp_path), Frame(str(tmp_path / "shot.exr")), 1)
    assert "overwrite the input" in e.value.problem
    assert output_path(str(tmp_path), Frame(str(tmp_path / "shot.exr")), 1, ext=".png") == str(tmp_path / "shot.png")


def test_output_path_plain_file(tmp_path):
    out = str(tmp_path / "den.exr")
    assert output_path(out, Frame("in.exr"), 1) == out
    with pytest.raises(RanadError) as e:
        output_path(out, Frame("in.0001.exr", 1), 2)
    assert e.value.problem == "several inputs need an output pattern (name.####.exr) or a folder"
    assert e.value.path == out


def test_two_inputs_into_one_output_are_refused(tmp_path):
    """Two folders' x.exr into one folder, or two shots' frame 1 into one pattern: the second overwrote the first
    and the run said it had written both."""
    out = tmp_path / "out"
    out.mkdir()
    a, b = Frame(str(tmp_path / "A" / "x.exr")), Frame(str(tmp_path / "B" / "x.exr"))
    with pytest.raises(RanadError) as e:
        output_paths(str(out) + os.sep, [a, b])
    assert e.value.path == str(out / "x.exr") and "A" in e.value.problem and "would both be written" in e.value.problem
    s1, s3 = Frame(str(tmp_path / "S1" / "s.0001.exr"), 1), Frame(str(tmp_path / "S3" / "s.0001.exr"), 1)
    with pytest.raises(RanadError):
        output_paths(str(tmp_path / "d.####.exr"), [s1, s3])
    assert output_paths(str(out), [a, Frame(str(tmp_path / "A" / "y.exr"))]) == [str(out / "x.exr"),
                                                                                  str(out / "y.exr")]


def test_frames_remember_their_pattern(tmp_path):
    """Two shots given together: each frame knows the pattern that found it, so a cross-frame window takes
    neighbours from its own shot (shot.window_of); equality ignores it."""
    from ranad_core.shot import window_of

    for d in ("S1", "S3"):
        (tmp_path / d).mkdir()
        touch(tmp_path / d, "s.0001.exr", "s.0002.exr", "s.0003.exr")
    p1, p3 = str(tmp_path / "S1" / "s.####.exr"), str(tmp_path / "S3" / "s.####.exr")
    seq = expand_inputs([p1, p3])
    assert [f.sequence for f in seq] == [p1] * 3 + [p3] * 3
    assert seq[0] == Frame(str(tmp_path / "S1" / "s.0001.exr"), 1)
    for k, d in ((1, "S1"), (4, "S3")):
        window, centre = window_of(seq[k], seq, 3)
        assert [f.path for f in window] == [str(tmp_path / d / f"s.000{n}.exr") for n in (1, 2, 3)] and centre == 1


# --- shards -------------------------------------------------------------------------------------


@pytest.mark.parametrize("n_items", [0, 1, 5, 10, 17])
@pytest.mark.parametrize("n_shards", [1, 2, 3, 4, 7])
def test_shards_cover_every_item_once(n_items, n_shards):
    items = [f"f{i}" for i in range(n_items)]
    parts = [shard(items, f"{i}/{n_shards}") for i in range(1, n_shards + 1)]
    flat = [x for p in parts for x in p]
    assert sorted(flat) == sorted(items)
    assert len(flat) == len(set(flat)) == n_items
    sizes = [len(p) for p in parts]
    assert max(sizes) - min(sizes) <= 1  # balanced


def test_shard_interleaves():
    assert shard(list(range(10)), "2/3") == [1, 4, 7]
    assert shard(list(range(10)), "1/1") == list(range(10))
    assert shard(list(range(10)), " 3 / 4 ") == [2, 6]


@pytest.mark.parametrize("bad", ["", "0/3", "4/3", "1/0", "a/b", "1", "1/2/3", "-1/2"])
def test_shard_bad_spec(bad):
    with pytest.raises(RanadError):
        shard([1, 2, 3], bad)
