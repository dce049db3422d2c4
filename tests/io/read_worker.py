"""Runs occmap readers on files under a memory and a time limit, one JSON line per case on stdout.

Used by the tests (``isolated.run_readers``) as ``python read_worker.py SPEC.json``. The spec holds
``memory`` (bytes of address space allowed beyond what the imports took), ``seconds`` (per case)
and ``cases``: ``[reader, path]`` pairs. Each case's outcome is ``ok`` (a result), ``error`` (an
OccmapError), ``memory`` (MemoryError: the limit was hit), ``hang`` (the time ran out) or
``crash`` (any other exception, with its traceback). A process that dies leaves its case without
a line; the caller reports it.
"""

from __future__ import annotations

import json
import resource
import signal
import sys
import traceback


def _readers():
    from occmap.io import read_kitti_bin, read_pcd, read_ply, read_scangraph, read_uos, read_xyz
    from occmap.io.carmen import read_carmen
    from occmap.io.mapserver import load_map
    from occmap.io.sonar import read_sonar_ring

    return {
        "carmen": read_carmen,
        "carmen-lenient": lambda p: read_carmen(p, lenient=True),
        "pcd": read_pcd,
        "ply": read_ply,
        "xyz": read_xyz,
        "kitti": read_kitti_bin,
        "uos": read_uos,
        "graph": read_scangraph,
        "sonar": read_sonar_ring,
        "map": load_map,
    }


class _OutOfTime(BaseException):
    pass


def _alarm(signum, frame):
    raise _OutOfTime


def main() -> None:
    with open(sys.argv[1]) as f:
        spec = json.load(f)
    readers = _readers()
    from occmap.errors import OccmapError

    with open("/proc/self/status") as f:
        size = next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmSize:"))
    limit = size + int(spec["memory"])
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    signal.signal(signal.SIGALRM, _alarm)
    for reader, path in spec["cases"]:
        detail = ""
        signal.setitimer(signal.ITIMER_REAL, float(spec["seconds"]))
        try:
            readers[reader](path)
            outcome = "ok"
        except OccmapError:
            outcome = "error"
        except MemoryError:
            outcome = "memory"
        except _OutOfTime:
            outcome = "hang"
        except BaseException:  # noqa: BLE001 - every other exception is what the tests look for
            outcome, detail = "crash", traceback.format_exc(limit=-6)
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
        print(json.dumps([reader, path, outcome, detail]), flush=True)


if __name__ == "__main__":
    main()
