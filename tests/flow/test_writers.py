"""The flow writers: decoded values are exactly the arrays written (OpenCV reads them back), any output path the
OS takes works (a directory named with a non-UTF-8 byte), and a pair's files are written in the background."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from sot_apps.flow.annotate import PairWriter
from sot_apps.flow.flo_io import UNKNOWN_FLOW, read_flo, write_flo
from sot_apps.flow.kitti_io import (
    encode_kitti_flow,
    kitti_flow_png,
    read_kitti_flow,
    write_kitti_flow,
    write_kitti_flows,
)
from sot_apps.flow.png import encode_png, encode_rows_png

REPO = Path(__file__).resolve().parents[2]
NON_UTF8 = os.fsdecode(b"out\xff\xfe")   # how Python hands a non-UTF-8 name over (surrogate escapes)


def _decode(data: bytes) -> np.ndarray:
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    return image[..., ::-1] if image.ndim == 3 else image   # OpenCV gives BGR; encode_png takes RGB


def _blobs(rng, shape, dtype, density):
    """Sparse rectangles and scattered pixels of random values over a constant background."""
    image = np.full(shape, 7, dtype=dtype)
    high = np.iinfo(dtype).max
    for _ in range(3):
        r0, c0 = rng.integers(0, shape[0]), rng.integers(0, shape[1])
        image[r0:r0 + rng.integers(1, 9), c0:c0 + rng.integers(1, 12)] = rng.integers(0, high, size=shape[2:] or None)
    scattered = rng.random(shape[:2]) < density
    image[scattered] = rng.integers(0, high, size=(int(scattered.sum()),) + shape[2:])
    return image


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("channels", [1, 3])
def test_png_decodes_to_the_array(dtype, channels):
    rng = np.random.default_rng(channels + 8 * np.dtype(dtype).itemsize)
    for shape2d in [(1, 1), (5, 1), (1, 7), (23, 41), (64, 300)]:
        shape = shape2d if channels == 1 else shape2d + (3,)
        background = 7 if channels == 1 else (7, 7, 7)
        for density in (0.0, 0.01, 0.3, 1.0):
            image = _blobs(rng, shape, dtype, density)
            np.testing.assert_array_equal(_decode(encode_png(image, background)), image)
            # with the caller's mask: a superset of the non-background pixels
            differs = (image != 7) if channels == 1 else (image != 7).any(axis=2)
            mask = differs | (rng.random(shape2d) < 0.2)
            np.testing.assert_array_equal(_decode(encode_png(image, background, mask)), image)
        # every pixel differs from the given background (the content spans run to both edges)
        image = rng.integers(0, np.iinfo(dtype).max, size=shape, dtype=dtype)
        np.testing.assert_array_equal(_decode(encode_png(image, 0)), image)


def test_png_rows_form_equals_the_full_image():
    rng = np.random.default_rng(5)
    image = np.zeros((50, 30, 3), np.uint16)
    rows = np.array([0, 3, 4, 30, 49])
    image[rows] = rng.integers(0, 65535, size=(len(rows), 30, 3))
    data = encode_rows_png(image[rows], rows, 50, (0, 0, 0))
    np.testing.assert_array_equal(_decode(data), image)
    assert data == encode_png(image, (0, 0, 0))


def test_png_pieces_cut_kept_and_reused():
    """Rows compressed in pieces (runs of rows, cut where asked) and pieces copied into a second image that shares
    them: both decode to their own arrays."""
    rng = np.random.default_rng(6)
    image = np.zeros((40, 25), np.uint16)
    rows = np.arange(5, 30)
    image[rows] = rng.integers(0, 65535, size=(len(rows), 25))
    pieces: dict = {}
    data = encode_rows_png(image[rows], rows, 40, 0, cuts=[7, 9], keep=pieces)
    np.testing.assert_array_equal(_decode(data), image)
    assert sorted(pieces) == [(0, 7), (7, 9), (9, 25)]
    changed = image.copy()
    changed[rows[7:9]] = rng.integers(0, 65535, size=(2, 25))   # only the rows of piece (7, 9) differ
    reused = {span: piece for span, piece in pieces.items() if span != (7, 9)}
    reused_data = encode_rows_png(changed[rows], rows, 40, 0, cuts=[7, 9], reuse=reused)
    np.testing.assert_array_equal(_decode(reused_data), changed)
    for png in (data, reused_data):   # zlib itself checks each stream's Adler-32 (combined from the pieces')
        idat = png[png.index(b"IDAT") + 4:png.index(b"IEND") - 8]
        assert len(zlib.decompress(idat)) == 40 * (1 + 25 * 2)


def _flow_1080p(rng):
    """A 1080p flow map with a few object-sized regions, values on and off the 1/64 grid, NaN and out-of-range."""
    flow = np.zeros((1080, 1920, 2), np.float32)
    valid = np.zeros((1080, 1920), bool)
    for r0, c0, h, w in [(400, 300, 200, 350), (500, 1500, 120, 200), (900, 0, 180, 90), (0, 1800, 60, 120)]:
        flow[r0:r0 + h, c0:c0 + w] = rng.uniform(-40, 40, size=(h, w, 2))
        valid[r0:r0 + h, c0:c0 + w] = rng.random((h, w)) < 0.97
    flow[450, 400] = (np.nan, 1.0)
    flow[460, 400] = (900.0, -900.0)   # clipped to the PNG's range
    return flow, valid


def test_kitti_png_and_flo_read_back_by_opencv_bit_identical(tmp_path):
    flow, valid = _flow_1080p(np.random.default_rng(0))
    write_kitti_flow(tmp_path / "f.png", flow, valid)
    written = cv2.imread(str(tmp_path / "f.png"), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(written, encode_kitti_flow(flow, valid))   # the array the format defines
    assert written[450, 400, 0] == 0 and written[460, 400].tolist() == [1, 0, 65535]   # NaN invalid, clipped
    write_flo(tmp_path / "f.flo", flow, valid)
    back = cv2.readOpticalFlow(str(tmp_path / "f.flo"))
    expected = np.where(valid[..., None], flow, UNKNOWN_FLOW)
    assert back.dtype == np.float32 and back.tobytes() == expected.tobytes()   # bit for bit, NaN included
    # and our reader reads what OpenCV writes
    cv2.writeOpticalFlow(str(tmp_path / "cv.flo"), expected)
    ours, known = read_flo(tmp_path / "cv.flo")
    np.testing.assert_array_equal(known, (np.abs(expected) < 1e9).all(axis=-1))


def test_float64_and_strided_flow_maps_are_written_like_their_float32_cast(tmp_path):
    """The fast float32 gathers are for C-ordered float32 maps; other maps are written as their float32 cast (.flo)
    and scaled in float64 (KITTI), as the formats define."""
    flow, valid = _flow_1080p(np.random.default_rng(2))
    wide = flow.astype(np.float64) + 1e-7                      # not representable in float32
    for given in (wide, np.asfortranarray(flow)):
        write_kitti_flow(tmp_path / "f.png", given, valid)
        np.testing.assert_array_equal(cv2.imread(str(tmp_path / "f.png"), cv2.IMREAD_UNCHANGED),
                                      encode_kitti_flow(given, valid))
        write_flo(tmp_path / "f.flo", given, valid)
        expected = np.where(valid[..., None], given.astype(np.float32), UNKNOWN_FLOW)
        assert cv2.readOpticalFlow(str(tmp_path / "f.flo")).tobytes() == expected.tobytes()


def test_writers_take_a_non_utf8_directory(tmp_path):
    out = tmp_path / NON_UTF8
    flow, valid = _flow_1080p(np.random.default_rng(1))
    write_kitti_flow(out / "f.png", flow, valid)
    write_flo(out / "f.flo", flow, valid)
    back, back_valid = read_kitti_flow(out / "f.png")
    np.testing.assert_array_equal(back_valid, valid & np.isfinite(flow).all(axis=-1))
    flo, known = read_flo(out / "f.flo")
    np.testing.assert_array_equal(known, back_valid)   # NaN is not a known flow in .flo either
    np.testing.assert_array_equal(flo[known], flow[known])
    assert sorted(os.listdir(os.fsencode(out))) == [b"f.flo", b"f.png"]   # no temporaries left


def test_flow_command_into_a_non_utf8_directory(tiny_dir, tmp_path):
    """Issue 26 item 8: this segfaulted (exit 139) in cv2.writeOpticalFlow and left temporary files."""
    out = os.fsencode(tmp_path) + b"/flow\xff"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    command = [sys.executable, "-m", "sot_apps.cli.main", "flow", os.fsencode(tiny_dir), "--from-annotations",
               "--camera", "front_camera", "--pairs", "0:3", "--vis", "--out", out, "--quiet"]
    done = subprocess.run(command, env=env, capture_output=True, timeout=120)
    assert done.returncode == 0, done.stderr.decode(errors="replace")
    root = out + b"/front_camera"
    names = {d: sorted(os.listdir(root + b"/" + d)) for d in (b"flow_occ", b"flow_noc", b"flo", b"instances", b"pairs")}
    assert all(len(v) == 3 for v in names.values()), names
    assert len(os.listdir(root + b"/vis")) == 6
    leftovers = [f for _, _, files in os.walk(out) for f in files if f.endswith(b".tmp")]
    assert leftovers == []
    flow, valid = read_kitti_flow(os.fsdecode(root + b"/flow_occ/000000.png"))
    flo, known = read_flo(os.fsdecode(root + b"/flo/000000.flo"))
    np.testing.assert_array_equal(known, valid)
    assert np.abs(flo[valid] - flow[valid]).max() <= 0.5 / 64 + 1e-6


def test_vis_is_written_only_when_asked(tiny_dir, tmp_path):
    from sot_apps.cli.main import main

    args = [str(tiny_dir), "--from-annotations", "--camera", "front_camera", "--pairs", "0:2", "--quiet"]
    assert main(["flow", *args, "--out", str(tmp_path / "a")]) == 0
    assert not (tmp_path / "a" / "front_camera" / "vis").exists()
    assert main(["flow", *args, "--out", str(tmp_path / "b"), "--vis"]) == 0
    assert sorted(p.name for p in (tmp_path / "b" / "front_camera" / "vis").iterdir()) == [
        "000000_flow.png", "000000_overlay.jpg", "000001_flow.png", "000001_overlay.jpg"]


def test_a_rerun_computes_again_the_pairs_whose_files_a_power_cut_emptied(tiny_dir, tmp_path):
    """The pairs' files are not synced one by one: after a power cut a renamed file may be empty or cut short on
    the disk. A rerun checks each finished pair's record and files and computes again the pairs that are not whole
    (the same bytes as before); a whole pair is left as it is, and stats.json lists every pair."""
    from sot_apps.cli.main import main

    args = ["flow", str(tiny_dir), "--from-annotations", "--camera", "front_camera", "--pairs", "0:4", "--quiet",
            "--out", str(tmp_path)]
    assert main(args) == 0
    root = tmp_path / "front_camera"
    files = sorted(p for p in root.rglob("*") if p.is_file() and p.parent.name != "front_camera")
    assert len(files) == 4 * 5

    def contents():   # the records without their compute time
        return {p: {k: v for k, v in json.loads(p.read_bytes()).items() if k != "time_ms"} if p.suffix == ".json"
                else p.read_bytes() for p in files}

    before = contents()
    damaged = [root / "flow_noc" / "000000.png", root / "flo" / "000001.flo", root / "pairs" / "000002.json"]
    for path, keep in zip(damaged, (0, 12, 0), strict=True):
        path.write_bytes(path.read_bytes()[:keep])
    cut = root / "instances" / "000003.png"
    cut.write_bytes(cut.read_bytes()[:-1])   # cut short by one byte: no whole IEND chunk
    untouched = root / "flo" / "000001.flo"
    stamps = {p: p.stat().st_mtime_ns for p in files if p.name.startswith("00000")}
    os.utime(root / "flow_occ" / "000000.png", ns=(1, 1))   # a file of a damaged pair: rewritten on the rerun
    assert main(args) == 0
    assert contents() == before
    assert (root / "flow_occ" / "000000.png").stat().st_mtime_ns != 1
    assert untouched.stat().st_mtime_ns != stamps[untouched]   # pair 1 was computed again
    stats = json.loads((root / "stats.json").read_text())
    assert [r["frame"] for r in stats["pairs"]] == [0, 1, 2, 3]
    assert not [p for p in root.rglob("*.tmp")]

    # a whole pair is skipped: none of its files is written again
    whole = [p for p in files if p.stem == "000001"]
    mtimes = {p: p.stat().st_mtime_ns for p in whole}
    assert main(args) == 0
    assert {p: p.stat().st_mtime_ns for p in whole} == mtimes


def test_pair_writer_records_follow_their_files_and_errors_propagate(tmp_path):
    order = []

    def job(name):
        return lambda: order.append(name)

    with PairWriter(workers=2, max_pending=1) as writer:
        for k in range(4):
            writer.submit([job(f"file{k}a"), job(f"file{k}b")], lambda k=k: order.append(f"record{k}"))
    records = [n for n in order if n.startswith("record")]
    assert records == [f"record{k}" for k in range(4)]
    for k in range(4):   # a record comes after both files of its pair
        assert order.index(f"record{k}") > max(order.index(f"file{k}a"), order.index(f"file{k}b"))

    def fail():
        raise OSError("disk on fire")

    written = []
    with pytest.raises(OSError, match="disk on fire"):
        with PairWriter(workers=1, max_pending=0) as writer:
            writer.submit([fail], lambda: written.append("record"))
    assert written == []   # no record for a pair whose files failed


def test_pair_writer_keeps_pair_order_when_files_finish_out_of_order_and_leaves_nothing_partial(tmp_path):
    """Earlier pairs' files finish last (a slow file per pair, slower for earlier pairs): the records still come in
    pair order, each after its own files. A pair whose file fails mid-write gets no record and leaves no file (atomic
    writes), and the pairs after it get none either."""
    import threading
    import time

    from sot_apps.io.atomic import atomic_path, write_bytes

    order, lock = [], threading.Lock()

    def file_job(k, part, delay):
        def run():
            time.sleep(delay)
            write_bytes(tmp_path / f"{k}{part}.bin", bytes(1000))
            with lock:
                order.append(f"file{k}{part}")
        return run

    def record(k):
        return lambda: order.append(f"record{k}")

    with PairWriter(workers=2, max_pending=3) as writer:
        for k in range(4):
            writer.submit([file_job(k, "a", 0.1 * (3 - k)), file_job(k, "b", 0.0)], record(k))
    finished = [n for n in order if n.startswith("file") and n.endswith("a")]
    assert finished != sorted(finished)                     # the files did finish out of pair order
    assert [n for n in order if n.startswith("record")] == [f"record{k}" for k in range(4)]
    for k in range(4):
        assert order.index(f"record{k}") > max(order.index(f"file{k}a"), order.index(f"file{k}b"))

    out = tmp_path / "failing"

    def half_written():
        with atomic_path(out / "000002.png") as tmp, open(tmp, "wb") as handle:
            handle.write(b"\x89PNG half")
            raise OSError("disk on fire")

    records = []
    with pytest.raises(OSError, match="disk on fire"):
        with PairWriter(workers=2, max_pending=0) as writer:
            for k in range(4):
                jobs = [half_written] if k == 2 else [lambda k=k: write_bytes(out / f"{k:06d}.png", b"ok")]
                writer.submit(jobs, lambda k=k: records.append(k))
    assert records == [0, 1]
    assert sorted(p.name for p in out.iterdir()) == ["000000.png", "000001.png"]   # no partial, no temporary


def test_occ_and_noc_pngs_written_together_decode_to_the_format_arrays(tmp_path):
    """flow_occ and flow_noc share one scaling of the flow (kitti_flow_pngs): each PNG still decodes, with OpenCV,
    to exactly the array the format defines for its own mask; a second mask that is not a subset works too."""
    rng = np.random.default_rng(3)
    flow, valid = _flow_1080p(rng)
    noc = valid & (rng.random(valid.shape) < 0.8)
    noc[400:420, :] = False                                  # rows whose valid pixels are all occluded
    for subset in (noc, noc | (rng.random(valid.shape) < 0.001)):   # a subset; not a subset
        write_kitti_flows(tmp_path / "occ.png", tmp_path / "noc.png", flow, valid, subset)
        for name, mask in (("occ.png", valid), ("noc.png", subset)):
            written = cv2.imread(str(tmp_path / name), cv2.IMREAD_UNCHANGED)
            np.testing.assert_array_equal(written, encode_kitti_flow(flow, mask), err_msg=name)
        assert (tmp_path / "occ.png").read_bytes() == kitti_flow_png(flow, valid)
        # (noc.png's deflate stream is cut into other pieces than kitti_flow_png's: same pixels, other bytes)


def test_kitti_values_of_float32_flow_round_as_the_exact_float64_formula():
    """float32 flow is scaled in float32 (exact: a power of two) and the offset added after rounding: ties (half
    steps of 1/64 px, both signs), the clipping edges and random values give what rint(flow * 64 + 2**15) in
    float64 gives."""
    from sot_apps.flow.kitti_io import _kitti_values

    steps = np.arange(-40000, 40000, dtype=np.float64)
    ties = ((steps + 0.5) / 64.0).astype(np.float32)
    rng = np.random.default_rng(9)
    values = np.concatenate([ties, (steps / 64.0).astype(np.float32), np.float32([511.99, 512.0, 600.0, -512.0,
                             -512.01, -600.0, 1e30, -1e30, 0.0, -0.0]), rng.normal(0, 50, 100_000).astype(np.float32)])
    flow = np.stack([values, values[::-1]], axis=1)
    exact = np.clip(np.rint(flow.astype(np.float64) * 64.0 + 2.0 ** 15), 0, 65535).astype(np.uint16)
    np.testing.assert_array_equal(_kitti_values(flow), exact)
