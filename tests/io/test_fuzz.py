"""Fuzzing every reader (issue 15): seeded mutations of real sample files (heads of them, where
they are large) and of small generated files — truncation, byte flips, special numbers, huge
counts, compressed and corrupt-compressed copies, compression bombs — each read in a child
process with a memory limit (1 GiB beyond the imports) and a time limit (10 s a case). Every
outcome must be a result or an OccmapError: never another exception, a hang, a dead process or
memory beyond the limit.

``OCCMAP_FUZZ_CASES`` sets the cases per reader (default 200; e.g. 3000 for a long run);
``OCCMAP_FUZZ_SEED`` the seed (default 0). The failing files stay in pytest's tmp folder.
"""

from __future__ import annotations

import bz2
import gzip
import lzma
import os
import random
from pathlib import Path

import numpy as np
import pytest
from isolated import run_readers

from occmap._data import find_shared_data
from occmap.io import write_pcd, write_ply
from occmap.io.mapserver import save_map

CASES = int(os.environ.get("OCCMAP_FUZZ_CASES", "200"))
SEED = int(os.environ.get("OCCMAP_FUZZ_SEED", "0"))
DATA = find_shared_data(Path(__file__).resolve().parents[1])

SPECIAL = [b"nan", b"-nan", b"inf", b"-inf", b"1e308", b"-1e308", b"1e400", b"-0", b"0", b"-1",
           b"4294967295", b"18446744073709551617", b"9" * 5000, b"\xb2", b"0x10", b"1_000", b""]
# gzip without a time stamp: the same seed gives the same bytes in every second
PACKERS = (lambda d: gzip.compress(d, 1, mtime=0), lambda d: bz2.compress(d, 1),
           lambda d: lzma.compress(d, preset=0))
HUGE_U32 = [b"\xff\xff\xff\xff", b"\xff\xff\xff\x7f", b"\x00\x00\x00\x80", b"\x01\x00\x00\x00"]


# ----------------------------------------------------------------------------------------------
# mutations


def _bomb_member() -> bytes:
    """One gzip member of 64 MiB of zeros (65 kB): appended to a gzip file, a bomb."""
    z = gzip.compress(bytes(1 << 20), compresslevel=9, mtime=0)
    return z * 64


def mutate(data: bytes, rng: random.Random, compressible: bool, bomb: bytes) -> bytes:
    """One seeded mutation of ``data`` (a few kinds, sometimes two in a row)."""
    for _ in range(rng.choice((1, 1, 2))):
        kind = rng.randrange(8 if compressible else 6)
        n = len(data)
        if kind == 0 and n:  # truncate
            data = data[: rng.randrange(n)]
        elif kind == 1 and n:  # flip bytes
            b = bytearray(data)
            for _ in range(rng.randint(1, 8)):
                b[rng.randrange(n)] = rng.randrange(256)
            data = bytes(b)
        elif kind == 2:  # a token replaced by a special number (text formats)
            tokens = data.split(b" ")
            if len(tokens) > 1:
                tokens[rng.randrange(len(tokens))] = rng.choice(SPECIAL)
                data = b" ".join(tokens)
        elif kind == 3 and n >= 4:  # a huge count (binary formats): four bytes overwritten
            at = rng.randrange(0, n - 3)
            if rng.random() < 0.5:
                at -= at % 4
            data = data[:at] + rng.choice(HUGE_U32) + data[at + 4:]
        elif kind == 4 and n:  # a piece repeated or cut out
            i, j = sorted(rng.randrange(n + 1) for _ in range(2))
            data = data[:i] + data[i:j] * rng.choice((0, 2, 50)) + data[j:]
        elif kind == 5:  # a digit string made enormous
            digits = [i for i, c in enumerate(data[:4096]) if 48 <= c <= 57]
            if digits:
                i = rng.choice(digits)
                data = data[:i] + rng.choice((b"9" * 30, b"9" * 5000, b"0" * 200)) + data[i:]
        elif kind == 6:  # compressed, sometimes corrupt
            packed = rng.choice(PACKERS)(data)
            if rng.random() < 0.5 and packed:
                b = bytearray(packed)
                b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
                packed = bytes(b[: rng.randrange(len(b) + 1)] if rng.random() < 0.3 else b)
            data = packed
        else:  # kind 7: a compression bomb behind the data
            data = gzip.compress(data, 1, mtime=0) + bomb
    return data


# ----------------------------------------------------------------------------------------------
# seeds: (file name, bytes) per reader; folder readers get a dict of files


def _head_lines(path: Path, lines: int) -> bytes:
    opener = {".gz": gzip.open, ".bz2": bz2.open}.get(path.suffix, open)
    with opener(path, "rb") as f:
        return b"".join(f.readline() for _ in range(lines))


def _real_points(n: int) -> np.ndarray:
    if DATA is not None:
        text = _head_lines(DATA / "scans3d" / "uos_3dtk" / "scan000.3d", n + 1)
        return np.loadtxt(text.decode().splitlines()[1:])[:, :3]
    return np.random.default_rng(3).normal(size=(n, 3)) * 10


def _pcd_head(n: int) -> bytes:
    """The real HDL-32 PCD's header and its first ``n`` binary records."""
    raw = (DATA / "scans3d" / "hdl32_pair" / "251370668.pcd").read_bytes()
    end = raw.index(b"DATA binary\n") + len(b"DATA binary\n")
    header = raw[:end].replace(b"WIDTH 69088", b"WIDTH %d" % n).replace(b"POINTS 69088", b"POINTS %d" % n)
    return header + raw[end: end + 16 * n]


def _written(tmp, name, write, *args, **kw) -> bytes:
    path = tmp / name
    write(path, *args, **kw)
    data = path.read_bytes()
    path.unlink()
    return data


def seeds(reader: str, tmp: Path) -> list:
    """The files mutated for ``reader``: real ones (when the shared data is there) and generated."""
    pts = _real_points(300)
    real = DATA is not None
    if reader in ("carmen", "carmen-lenient"):
        out = [("gen.log", b"PARAM robot_front_laser_max 50\nFLASER 4 1 2 3 4 1 2 0.5 1 2 0.5 100.5 h 7.25\n"
                b"ROBOTLASER1 0 -0.6 1.2 0.3 30 0.01 0 3 1 2 3 2 0.5 0.6 3 4 0.5 2.9 3.9 0.1 0.5 0.1 0.3 0.2 0 55.5 h 66.5\n"
                b"ODOM 0 0 0 0 0 0 1 h 1\n")]
        if real:
            out += [("intel.log", _head_lines(DATA / "carmen" / "intel-corrected.log.gz", 40)),
                    ("fr079.clf", _head_lines(DATA / "carmen" / "fr079-raw.clf.bz2", 60))]
        return out
    if reader == "pcd":
        out = [("gen.pcd", _written(tmp, "g.pcd", write_pcd, pts)),
               ("gen_ascii.pcd", _written(tmp, "a.pcd", write_pcd, pts[:100], binary=False))]
        return out + ([("hdl32.pcd", _pcd_head(300))] if real else [])
    if reader == "ply":
        colors = np.random.default_rng(1).integers(0, 256, (len(pts), 3))
        return [("gen.ply", _written(tmp, "g.ply", write_ply, pts)),
                ("gen_rgb.ply", _written(tmp, "c.ply", write_ply, pts, colors)),
                ("gen_ascii.ply", _written(tmp, "a.ply", write_ply, pts[:100], binary=False))]
    if reader == "xyz":
        out = [("gen.xyz", b"# x y z\n1 2 3\n4.5 -6e-3 7 99\n\n8 9 10\n")]
        return out + ([("uos.xyz", _head_lines(DATA / "scans3d" / "uos_3dtk" / "scan000.3d", 200))] if real else [])
    if reader == "kitti":
        return [("gen.bin", np.column_stack([pts, np.ones(len(pts))]).astype("<f4").tobytes())]
    if reader == "uos":
        if not real:
            return []
        folder = DATA / "scans3d" / "uos_3dtk"
        return [{"scan000.3d": _head_lines(folder / "scan000.3d", 200),
                 "scan000.frames": (folder / "scan001.frames_slam6d_2009").read_bytes(),
                 "scan000.pose": (folder / "scan001.pose").read_bytes()}]
    if reader == "graph":
        return [("spherical.graph", (DATA / "octomap" / "spherical_scan.graph").read_bytes())] if real else []
    if reader == "sonar":
        gen = {"measurement.txt": b"1 5110 5110 2320 2360 5110 5110 2160 1190\n2 1 2 3 4 5 6 7 8\n",
               "poses.txt": b"1 0 0 0\n2 10 20 3599\n"}
        if not real:
            return [gen]
        return [gen, {"measurement.txt": (DATA / "sonar" / "measurement.txt").read_bytes(),
                      "poses.txt": (DATA / "sonar" / "poses.txt").read_bytes()}]
    if reader == "map":
        occ = np.random.default_rng(2).integers(-1, 101, (20, 30)).astype(np.int8)
        out = []
        for fmt, mode in (("pgm", "trinary"), ("png", "scale")):
            folder = tmp / f"seed-{fmt}"
            save_map(folder / "m.yaml", occ, 0.05, (-1.0, 2.0), image_format=fmt, mode=mode)
            yaml = (folder / "m.yaml").read_bytes()
            out.append({"m.yaml": yaml, f"m.{fmt}": (folder / f"m.{fmt}").read_bytes()})
            # without the digest, a mutated image reaches the image decoder
            out.append({"m.yaml": yaml.split(b"# the image")[0], f"m.{fmt}": (folder / f"m.{fmt}").read_bytes()})
        if real:
            out.append({"m.yaml": b"image: ref.png\nresolution: 0.05\norigin: [0, 0, 0]\n"
                                  b"occupied_thresh: 0.65\nfree_thresh: 0.196\n",
                        "ref.png": (DATA / "sonar" / "Map_reference.png").read_bytes()})
        return out
    raise AssertionError(reader)


# ----------------------------------------------------------------------------------------------
# cases

READERS = ["carmen", "carmen-lenient", "pcd", "ply", "xyz", "kitti", "uos", "graph", "sonar", "map"]
ENTRY = {"uos": "scan000.3d", "sonar": None, "map": "m.yaml"}


def make_cases(reader: str, tmp: Path, n: int, seed: int, bomb: bytes) -> list[tuple[str, Path]]:
    rng = random.Random(f"{reader}-{seed}")
    pool = seeds(reader, tmp)
    if not pool:
        pytest.skip(f"{reader}: no sample files without the shared data (../shared/data)")
    cases = []
    for i in range(n):
        seed_file = rng.choice(pool)
        if isinstance(seed_file, dict):  # a folder: one of its files mutated
            folder = tmp / f"case{i:05d}"
            folder.mkdir()
            victim = rng.choice(sorted(seed_file))
            for name, data in seed_file.items():
                body = mutate(data, rng, reader != "map" or name.endswith(".yaml"), bomb) if name == victim else data
                (folder / name).write_bytes(body)
            entry = ENTRY[reader]
            cases.append((reader, folder if entry is None else folder / entry))
        else:
            name, data = seed_file
            path = tmp / f"case{i:05d}-{name}"
            path.write_bytes(mutate(data, rng, True, bomb))
            cases.append((reader, path))
    return cases


@pytest.fixture(scope="module")
def bomb():
    return _bomb_member()


@pytest.mark.parametrize("reader", READERS)
def test_fuzzed_files_give_a_result_or_an_occmap_error(tmp_path, reader, bomb):
    cases = make_cases(reader, tmp_path, CASES, SEED, bomb)
    results = run_readers(cases, memory=1 << 30, seconds=10.0)
    assert len(results) == len(cases)
    tally: dict[str, int] = {}
    for _, _, result, _ in results:
        tally[result] = tally.get(result, 0) + 1
    bad = [r for r in results if r[2] not in ("ok", "error")]
    print(f"{reader}: {len(cases)} cases {tally}")
    assert not bad, f"{len(bad)} of {len(cases)} cases failed, e.g.\n" + "\n".join(
        f"{path}: {result}\n{detail}" for _, path, result, detail in bad[:3]
    )


def test_mutations_are_seeded_and_reach_every_kind(tmp_path, bomb):
    runs = []
    for run in ("a", "b"):
        (tmp_path / run).mkdir()
        runs.append([p.read_bytes() for _, p in make_cases("xyz", tmp_path / run, 40, 1, bomb)])
    assert runs[0] == runs[1]
    rng = random.Random(0)
    data = b"1 2 3\n4 5 6\n" * 50
    outs = [mutate(data, rng, True, bomb) for _ in range(300)]
    assert any(len(o) < len(data) for o in outs) and any(bomb in o for o in outs)
    assert any(o[:2] == b"\x1f\x8b" for o in outs) and any(b"nan" in o or b"inf" in o for o in outs)
