"""``occmap view`` on OctoMap's sample maps: how long until the scene is sent, the server's peak
memory, and how many voxels it draws against the leaves a viewer drawing every leaf (octovis)
draws.

Each round starts ``occmap view MAP --port 0 --no-browser`` in a fresh process, as a user does,
and times it from the start of the process to the line announcing the address (the map read, its
levels of detail picked and the whole scene handed to the server; the command prints the part of
it spent in the viewer itself). With Chromium on the machine a headless browser then opens the
address and the time until the map's colours show on its screenshot is added (software graphics:
a real GPU draws faster). The server's peak resident memory (``VmHWM``) is read after the browser
has the scene, before the process is stopped. Medians of alternating rounds.

    python benchmarks/bench_viewer.py [--rounds N] [--no-write]
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import ROOT, shared_data, write_section  # noqa: E402

sys.path.insert(0, str(ROOT / "tests" / "viz"))
from headless import ARGS, CHROMIUM, VIEW, ramp_pixels  # noqa: E402  (the tests' browser settings)

BIN = Path(sys.executable).parent


def drawn_seconds(browser, url: str, timeout: float = 60.0) -> float:
    """Seconds from opening ``url`` in a new tab until 2,000 pixels of the height ramp show."""
    page = browser.new_page(viewport=VIEW)
    t0 = time.perf_counter()
    page.goto(url)
    while ramp_pixels(page.screenshot()) < 2000:
        if time.perf_counter() - t0 > timeout:
            raise RuntimeError(f"{url}: the map did not show within {timeout:g} s")
        page.wait_for_timeout(100)
    seconds = time.perf_counter() - t0
    page.close()
    return seconds


def octovis_run(path: Path) -> tuple[float, float] | None:
    """octovis (OctoMap's viewer) opening ``path`` on a virtual display (Xvfb, software OpenGL):
    its peak resident memory (bytes) and the CPU seconds it spent until it went idle (the map read
    and drawn). None when octovis or Xvfb is not installed."""
    if not (shutil.which("octovis") and shutil.which("Xvfb")):
        return None
    display = ":87"
    xvfb = subprocess.Popen(["Xvfb", display, "-screen", "0", "1280x800x24"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    time.sleep(1.5)
    viewer = subprocess.Popen(["octovis", str(path)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              env=dict(os.environ, DISPLAY=display, LIBGL_ALWAYS_SOFTWARE="1"))
    try:
        cpu, still = -1.0, 0
        while still < 6:  # idle for 3 s
            time.sleep(0.5)
            fields = Path(f"/proc/{viewer.pid}/stat").read_text().rsplit(")", 1)[1].split()
            now = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
            still, cpu = (still + 1, cpu) if now == cpu else (0, now)
        status = Path(f"/proc/{viewer.pid}/status").read_text()
        return int(re.search(r"VmHWM:\s+(\d+) kB", status).group(1)) * 1024, cpu
    finally:
        for proc in (viewer, xvfb):
            proc.kill()
            proc.wait()


def one_run(path: Path, browser) -> dict:
    t0 = time.perf_counter()
    proc = subprocess.Popen([str(BIN / "occmap"), "view", str(path), "--port", "0", "--no-browser"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, url = [], None
    while url is None:
        line = proc.stdout.readline()
        if not line:
            raise RuntimeError(f"occmap view stopped: {proc.stderr.read()}")
        out.append(line)
        found = re.search(r"serving at (\S+)", line)
        url = found and found.group(1)
    run = {"start_to_scene": time.perf_counter() - t0, "output": "".join(out)}
    run["in_viewer"] = float(re.search(r"scene sent in (\S+) s", run["output"]).group(1))
    drawn = re.search(r"drawn: ([\d,]+) occupied boxes at depth (\d+) \(([\d,]+) occupied leaves\)", run["output"])
    run["drawn"], run["depth"], run["leaves"] = int(drawn.group(1).replace(",", "")), int(drawn.group(2)), \
        int(drawn.group(3).replace(",", ""))
    if browser is not None:
        run["browser"] = drawn_seconds(browser, url)
    status = Path(f"/proc/{proc.pid}/status").read_text()
    run["peak_rss"] = int(re.search(r"VmHWM:\s+(\d+) kB", status).group(1)) * 1024
    proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=30)
    if proc.returncode != 0:
        raise RuntimeError(f"occmap view ended with {proc.returncode}")
    return run


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--no-write", action="store_true", help="print only; leave BENCHMARKS.md alone")
    args = ap.parse_args()
    data = shared_data()
    if data is None:
        print("shared data not found: the OctoMap sample files are needed", file=sys.stderr)
        return 1
    import octomap

    maps = {name: data / "octomap" / name for name in ("geb079.bt", "fr_079.bt")}
    leaves = {}
    for name, path in maps.items():  # what octovis draws: every leaf (occupied, and free when shown)
        t = octomap.OcTree(0.1)
        t.readBinary(str(path).encode())
        occupied = sum(1 for leaf in t.begin_leafs() if t.isNodeOccupied(leaf))
        leaves[name] = (t.size(), occupied, t.getNumLeafNodes() - occupied)

    octovis = {name: octovis_run(path) for name, path in maps.items()}
    runs = {name: [] for name in maps}
    load = os.getloadavg()[0]
    browser = playwright = None
    if CHROMIUM:
        from playwright.sync_api import sync_playwright

        playwright = sync_playwright().start()
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=ARGS)
    try:
        for _ in range(args.rounds):
            for name, path in maps.items():
                runs[name].append(one_run(path, browser))
    finally:
        if browser is not None:
            browser.close()
            playwright.stop()

    med = lambda name, key: statistics.median(r[key] for r in runs[name])  # noqa: E731
    rows = []
    for name in maps:
        r = runs[name][0]
        nodes, occupied, free = leaves[name]
        browser_cell = f"{med(name, 'browser'):.2f}" if browser is not None else "no chromium"
        peak = max(x["peak_rss"] for x in runs[name]) / 2**20
        o = octovis[name]
        octovis_cells = f"{o[0] / 2**20:.0f} | {o[1]:.2f}" if o else "not installed | "
        rows.append(f"| {name} | {nodes:,} | {occupied:,} / {free:,} | {r['drawn']:,} (depth {r['depth']}) | "
                    f"{med(name, 'start_to_scene'):.2f} | {med(name, 'in_viewer'):.2f} | {browser_cell} | {peak:.0f} | "
                    f"{octovis_cells} |")
        print(f"{name}: start to scene {med(name, 'start_to_scene'):.2f} s (viewer {med(name, 'in_viewer'):.2f} s), "
              f"browser {browser_cell} s, peak RSS {peak:.0f} MiB, drawn {r['drawn']:,} of {occupied:,} occupied "
              f"leaves ({nodes:,} nodes)")
    lines = [
        "## 3D viewer in the browser (`benchmarks/bench_viewer.py`)",
        "",
        f"`occmap view MAP --port 0 --no-browser` in a fresh process, median of {args.rounds} alternating rounds: "
        "seconds from the start of the process until the whole scene is handed to the server (file read, level of "
        "detail, scene; of which the viewer's own part after the interpreter and imports), then until a headless "
        "Chromium (software graphics, SwiftShader) shows the map's colours on its screenshot, and the server "
        "process's peak resident memory (largest of the rounds) with the browser connected. Target for fr_079.bt: "
        "≤ 3 s and ≤ 1 GB. octovis draws every leaf (the free ones too when asked); occmap draws the occupied "
        "nodes of the deepest depth with at most 500,000 of them (free space on demand, likewise capped), as "
        "square points by default. Counts from OctoMap's own reader (octomap-python). octovis (the Debian "
        "package, on a virtual X display with software OpenGL, its default view: occupied leaves) once per map: "
        "its peak resident memory, and the CPU time it spent until it went idle (file read and drawn). Load average "
        f"{load:.1f} on {os.cpu_count()} cores when the runs began (the machine is shared).",
        "",
        "| map | nodes | leaves octovis draws: occupied / free | occmap draws (occupied) | start → scene sent (s) | "
        "in the viewer (s) | → drawn in Chromium (s) | peak RSS (MiB) | octovis peak RSS (MiB) | octovis CPU (s) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        *rows,
    ]
    if not args.no_write:
        write_section("bench_viewer", "\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
