"""``occmap view PATH``: an interactive 3D view of a map in the browser, served at
``http://127.0.0.1:PORT/`` until interrupted (:class:`occmap.viz.viewer.Viewer`)."""

from __future__ import annotations

from . import _options


def add_parser(subparsers):
    p = subparsers.add_parser("view", help="show a map in 3D in the browser (octrees, tile stores, point clouds, "
                              "2D maps) until interrupted")
    p.add_argument("file", help="a .bt / .ot file, a tile store folder, a point cloud, a scan graph (.graph), a "
                   "map_server .yaml or a recorded run (.npz from localize, map2d or local --record)")
    p.add_argument("--port", type=_options.port, default=8080, help="TCP port (default 8080; 0: any free one; one in use is an error)")
    p.add_argument("--no-browser", action="store_true", help="only serve; do not open a browser tab")
    p.add_argument("--max-voxels", type=_options.count, default=None,
                   help="boxes drawn at most per class of space (default 500,000; coarser octree levels beyond it)")
    return p


#: Seconds the command waits for the server to close after Ctrl-C.
_STOP_SECONDS = 10.0


def run(args) -> int:
    import signal
    import threading
    import webbrowser

    from ..viz.viewer import DEFAULT_MAX_VOXELS, Viewer

    viewer = Viewer(args.file, port=args.port, max_voxels=args.max_voxels or DEFAULT_MAX_VOXELS)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):  # (before the address is printed: Ctrl-C may follow at once)
        signal.signal(sig, lambda *_: stop.set())
    try:
        t = viewer.timings
        print(f"{viewer.scene.path}: {viewer.scene.kind}, {viewer.scene.summary}")
        if viewer.occupied is not None:
            o = viewer.occupied
            print(f"  drawn: {o.voxels.count:,} occupied boxes at depth {o.depth} ({o.leaves:,} occupied leaves)")
        print(f"  read in {t['read']:.2f} s, scene sent in {t['scene']:.2f} s")
        print(f"serving at {viewer.url} (Ctrl-C to stop)", flush=True)
        if not args.no_browser:
            webbrowser.open(viewer.url)
        stop.wait()
    finally:
        # (bounded: a server thread stuck in its teardown must not keep Ctrl-C from ending the command)
        closing = threading.Thread(target=viewer.stop, daemon=True)
        closing.start()
        closing.join(_STOP_SECONDS)
    print("stopped")
    return 0
