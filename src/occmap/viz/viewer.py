"""An interactive 3D viewer in the browser: :class:`Viewer` serves a map at
``http://127.0.0.1:PORT/`` through `viser <https://viser.studio>`_ (a web 3D viewer for robotics,
with its built client in its wheel: it works offline).

What it draws (coordinates are the map's, metres, z up):

- **octrees** (``.bt``/``.ot``, octree tile stores): occupied nodes as boxes coloured by height
  (or by probability), free space on demand, as translucent boxes. Level of detail: a coarse
  depth (:data:`~occmap.viz._lod.COARSE_DEPTH`) goes out first, then the deepest depth whose
  occupied nodes number at most ``max_voxels`` (an inner node holds the maximum of its children,
  so a coarser depth hides no obstacle: :mod:`occmap.viz._lod`);
- **point clouds** and **scan graphs**: points coloured by height, and the sensor's path;
- **2D maps** (map_server ``.yaml``, 2D tile stores): the map's picture as a plane at z = 0;
- **recorded localization runs** (``.npz``, :mod:`occmap.localize.recording`): the map as a plane
  and, at the step the panel's time slider picks (or "Play" advances, at the run's pace times a
  speed), the particles, the estimated pose as a frame, the estimate's track so far and the
  reference poses so far (where the run had them);
- **recorded mapping runs** (:mod:`occmap.mapping2d_recording`): the map as it was at the step,
  the sensor's path so far and a frame at its pose;
- **recorded local-map runs** (:mod:`occmap.local.recording`): the costmap at the step as a plane
  where the window was, the robot's path and pose, the tracks as their footprints' outlines.
  A recorded run's kind is its file's ``format`` entry (:mod:`occmap._recordings`).

The panel holds the colour mode, the free-space switch, a slice (cut the map above a height, or
keep the one layer a height crosses) and a way to open another map in the running server (a
file next to the first one, or any path); :meth:`Viewer.load` does the same from Python.
"""

from __future__ import annotations

import functools
import math
import threading
import time

import numpy as np

from .. import checks
from ..errors import InvalidArgumentError, OccmapError
from ..logodds import probability
from ..octree.keys import DEPTH
from ._lod import COARSE_DEPTH, Level, Voxels, cut, pick_level, ramp
from ._maps import Plane, Scene, block_max, occupancy_plane, open_scene, viewable
from ._scene3d import STYLES, add_boxes, camera_view, close_server, new_server

#: Boxes drawn at most per class of space (occupied, free): about 20 MB to the browser, smooth on
#: an integrated GPU. OctoMap's largest sample (fr_079.bt) has 372,904 occupied leaves.
DEFAULT_MAX_VOXELS = 500_000
#: Points of a cloud drawn at most (every k-th point beyond it).
MAX_POINTS = 2_000_000
#: Cells a side of a map drawn step by step, at most (beyond it, blocks of k × k cells drawn as
#: one): a step's picture is encoded anew, about 0.25 s for a million pixels.
MAX_PLANE_CELLS = 1024
#: Maps listed beside the one shown, at most.
MAX_LISTED = 500

FREE_COLOR = (120, 200, 140)
PATH_COLOR = (230, 40, 40)
PARTICLE_COLOR = (255, 140, 0)
ESTIMATE_COLOR = (30, 90, 230)
REFERENCE_COLOR = (20, 170, 60)
TRACK_COLOR = (0, 170, 60)
TENTATIVE_COLOR = (120, 220, 140)
#: Redraws a second at most while "Play" is on; steps a second of a run with no pace of its own.
PLAY_RATE = 10.0
#: "Play"'s speeds: times the run's recorded pace.
PLAY_SPEEDS = {"1×": 1.0, "2×": 2.0, "5×": 5.0, "10×": 10.0, "50×": 50.0}
SLICES = {"off": "off", "cut above z": "below", "only at z": "at"}
COLOURS = ("height", "probability")


class Viewer:
    """A map served to the browser at :attr:`url` until :meth:`stop` (or the end of a ``with``).

    Parameters
    ----------
    path : str or Path
        What to show (see the module docstring).
    port : int
        TCP port; 0 picks a free one (:attr:`port` tells which).
    host : str
        Address to bind; the loopback interface by default, so only this computer sees the map.
    max_voxels : int
        Boxes drawn at most per class of space (level of detail).
    style : str
        ``"points"`` (square points as wide as the boxes: one vertex each, smooth with half a
        million of them even on software graphics) or ``"boxes"`` (instances of one shaded cube,
        12 triangles each); the panel switches it.

    Attributes
    ----------
    scene : the map shown (:class:`occmap.viz._maps.Scene`)
    occupied : :class:`occmap.viz._lod.Level` or None, the occupied boxes drawn (depth, count, leaves)
    timings : dict, seconds from the start of the last :meth:`load` to ``"read"`` (file read),
        ``"coarse"`` (coarse level sent) and ``"scene"`` (the whole scene sent)
    """

    def __init__(self, path, port: int = 8080, host: str = "127.0.0.1", max_voxels: int = DEFAULT_MAX_VOXELS,
                 style: str = "points"):
        self.max_voxels = checks.count("max_voxels", max_voxels, minimum=1)
        port = checks.count("port", port, minimum=0)
        if port > 65535:
            raise InvalidArgumentError(f"port must be 0 .. 65535, got {port}")
        if style not in STYLES:
            raise InvalidArgumentError(f"style must be one of {STYLES}, got {style!r}")
        self.server = new_server(host, port)  # silent: the caller prints the address
        if port and self.server.get_port() != port:  # viser moves on to a free port: the user named this one
            taken = self.server.get_port()
            close_server(self.server)
            raise InvalidArgumentError(f"port {port} on {host} is in use (the next free one is {taken}): "
                                       "choose another, or 0 for any free one")
        self._lock = threading.RLock()
        self.scene: Scene | None = None
        self.occupied: Level | None = None
        self._free: Level | None = None
        self._points: Voxels | None = None
        self._z_range = (0.0, 1.0)
        self._marker = 1.0
        self._bounds = (np.zeros(3), np.ones(3))
        self._loading = False
        self.timings: dict[str, float] = {}
        self._nodes_at = None
        self._build_panel()
        self._style.value = style
        self._closing = threading.Event()
        try:
            self.load(path)
        except BaseException:
            self.server.stop()
            raise
        threading.Thread(target=self._play_loop, name="occmap-viewer-play", daemon=True).start()

    @property
    def free(self) -> Level | None:
        """The free boxes drawn (None until free space is first shown)."""
        return self._free

    @property
    def step(self) -> int | None:
        """The step of a recorded run drawn (None for a map without one); set it to draw another,
        as the panel's time slider does."""
        return int(self._step.value) if self.scene is not None and self.scene.recording is not None else None

    @step.setter
    def step(self, value: int) -> None:
        rec = self.scene.recording if self.scene is not None else None
        if rec is None:
            raise InvalidArgumentError(f"{self.scene.path.name} is not a recorded run: it has no steps")
        step = checks.count("step", value, minimum=0)
        if step >= len(rec):
            raise InvalidArgumentError(f"step must be 0 .. {len(rec) - 1} (the run's steps), got {step}")
        self._step.value = step

    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def url(self) -> str:
        return f"http://{self.server.get_host()}:{self.port}/"

    def stop(self) -> None:
        """Close the server (its port is free again)."""
        self._closing.set()
        self.server.stop()

    def __enter__(self) -> Viewer:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------ loading

    def load(self, path) -> Scene:
        """Show ``path`` instead of the current map, in every open browser tab. Raises
        :class:`~occmap.errors.OccmapError` when it cannot be read (the current map stays)."""
        with self._lock:
            start = time.perf_counter()
            scene = open_scene(path)
            timings = {"read": time.perf_counter() - start}
            self._loading = True
            try:
                if self.scene is not None:
                    self.server.scene.remove_by_name("/map")
                self.scene, self.occupied, self._free, self._points = scene, None, None, None
                self._nodes_at = functools.lru_cache(maxsize=2)(scene.nodes_at) if scene.nodes_at else None
                if self._nodes_at is not None:
                    self.occupied = self._level(self._is_occupied, 0, coarse=True)
                    self._draw_voxels()
                    timings["coarse"] = time.perf_counter() - start
                    self.occupied = self._level(self._is_occupied, 0)
                if scene.points is not None:
                    pts = scene.points[::max(1, math.ceil(len(scene.points) / MAX_POINTS))]
                    self._points = Voxels(pts, np.full(len(pts), scene.resolution, np.float32),
                                          np.zeros(len(pts), np.float32))
                self._bounds = self._drawn_bounds()
                self._update_panel()
                self._draw_all()
                self._aim_cameras()
            finally:
                self._loading = False
            timings["scene"] = time.perf_counter() - start
            self.timings = timings
            return scene

    def _level(self, keep, column: int, coarse: bool = False) -> Level:
        """The boxes of one class drawn (``keep``; ``column`` its entry in the scene's counts), at
        :data:`~occmap.viz._lod.COARSE_DEPTH` at most for a first view."""
        top = COARSE_DEPTH if coarse else DEPTH
        counts = self.scene.counts
        return pick_level(lambda d: self._nodes_at(min(d, top)), keep, self.max_voxels,
                          None if counts is None else lambda d: counts(min(d, top))[column])

    def _is_occupied(self, v: Voxels) -> np.ndarray:
        return v.log_odds >= self.scene.occupied_log_odds

    def _is_free(self, v: Voxels) -> np.ndarray:
        return v.log_odds < self.scene.occupied_log_odds

    def _open_from_panel(self, path: str) -> None:
        try:
            self.load(path)
        except (OccmapError, OSError) as e:
            self._info.content = f"**could not open** `{path}`: {e}\n\n{self._describe()}"

    # ------------------------------------------------------------------ drawing

    def _draw_all(self) -> None:
        lo, hi = self._bounds
        self._marker = max(float(np.linalg.norm(hi - lo)) / 100, 2 * self.scene.resolution)
        self.server.scene.add_frame("/map/origin", axes_length=5 * self._marker, axes_radius=self._marker / 4)
        self._draw_voxels()
        self._draw_free()
        self._draw_points()
        self._draw_plane()
        self._draw_path()
        self._draw_slice_plane()
        self._draw_step()

    def _slice(self, v: Voxels) -> Voxels:
        mode = SLICES[self._slice_mode.value]
        return v if mode == "off" else v.subset(cut(v, mode, float(self._z.value)))

    def _colors(self, v: Voxels, free: bool) -> np.ndarray:
        """Height ramp over the drawn heights (free space one colour), or the same ramp over the
        occupancy probability 0 … 1 (a ``.bt`` holds only its two clamping values)."""
        if self._colour.value == "probability":
            return ramp(probability(v.log_odds), (0.0, 1.0))
        if free:
            return np.array(FREE_COLOR, np.uint8)
        lo, hi = self._z_range
        if SLICES[self._slice_mode.value] == "below":  # the ramp spans what the cut leaves
            hi = max(lo, min(hi, float(self._z.value)))
        return ramp(v.centers[:, 2], (lo, hi))

    def _boxes(self, name: str, v: Voxels, colors, see_through: bool = False) -> None:
        add_boxes(self.server.scene, name, v, colors, self._style.value, see_through)

    def _draw_voxels(self) -> None:
        if self.occupied is None:
            return
        all_v = self.occupied.voxels
        if all_v.count:
            self._z_range = (float(all_v.centers[:, 2].min()), float(all_v.centers[:, 2].max()))
        v = self._slice(all_v)
        self._boxes("/map/occupied", v, self._colors(v, free=False))

    def _draw_free(self) -> None:
        if self._nodes_at is None or not self._show_free.value:
            self.server.scene.remove_by_name("/map/free")
            return
        if self._free is None:
            self._free = self._level(self._is_free, 1)
        v = self._slice(self._free.voxels)
        self._boxes("/map/free", v, self._colors(v, free=True), see_through=True)

    def _draw_points(self) -> None:
        if self._points is None:
            return
        all_p = self._points
        if all_p.count:
            self._z_range = (float(all_p.centers[:, 2].min()), float(all_p.centers[:, 2].max()))
        p = self._slice(all_p)
        self.server.scene.add_point_cloud("/map/points", p.centers, self._colors(p, free=False),
                                          point_size=self.scene.resolution, point_shape="square",
                                          precision="float32", point_shading="flat")

    def _draw_plane(self) -> None:
        if self.scene.plane is not None:
            self._draw_image(self.scene.plane)

    def _draw_image(self, plane: Plane) -> None:
        half = plane.yaw / 2
        self.server.scene.add_image("/map/plane", plane.rgb, plane.width, plane.height, format="png",
                                    position=plane.center, wxyz=(np.cos(half), 0.0, 0.0, np.sin(half)),
                                    cast_shadow=False, receive_shadow=False)

    def _draw_path(self) -> None:
        track = self.scene.sensor_path
        if track is None or not len(track):
            return
        self.server.scene.add_point_cloud("/map/sensor", track.astype(np.float32), PATH_COLOR,
                                          point_size=self._marker, point_shape="circle",
                                          precision="float32", point_shading="flat")
        if len(track) > 1:
            segments = np.stack([track[:-1], track[1:]], axis=1).astype(np.float32)
            self.server.scene.add_line_segments("/map/sensor_path", segments, PATH_COLOR, line_width=3.0)

    def _draw_step(self) -> None:
        """A recorded run at the slider's step, drawn by its kind, a little above the map plane."""
        rec = self.scene.recording
        if rec is None:
            return
        i = min(int(self._step.value), len(rec) - 1)  # a slider spans two steps at least
        draw = {"localization run": self._draw_localization, "mapping run": self._draw_mapping,
                "local map run": self._draw_local_map}[self.scene.kind]
        self._info.content = (f"{self._describe()}\n\nstep {i + 1:,} of {len(rec):,}, "
                              f"t = {rec.stamps[i] - rec.stamps[0]:.2f} s{draw(rec, i, self._marker / 4)}")

    def _draw_localization(self, rec, i: int, z: float) -> str:
        """Particles, the estimate (a frame, x ahead) and the reference, with the estimate's track
        (a line) and the reference poses (dots) up to step ``i``."""
        particles = rec.particles[i]
        particles = particles[np.isfinite(particles[:, 0])]
        self.server.scene.add_point_cloud("/map/run/particles", _at_height(particles, z), PARTICLE_COLOR,
                                          point_size=self._marker / 2, point_shape="circle",
                                          precision="float32", point_shading="flat")
        self._draw_track("/map/run/estimate_track", rec.estimates[: i + 1], ESTIMATE_COLOR, z)
        # the reference as dots: a corrected log pairs with one scan in ~15 (Intel), too few for a line
        known = rec.reference[: i + 1]
        known = known[np.isfinite(known[:, 0])]
        self.server.scene.remove_by_name("/map/run/reference_track")
        if len(known):
            self.server.scene.add_point_cloud("/map/run/reference_track", _at_height(known, z), REFERENCE_COLOR,
                                              point_size=self._marker / 4, point_shape="circle",
                                              precision="float32", point_shading="flat")
        self._draw_pose("/map/run/estimate", rec.estimates[i], z)
        ref = rec.reference[i]
        x, y, _ = rec.estimates[i]
        if np.isfinite(ref).all():
            self.server.scene.add_point_cloud("/map/run/reference", _at_height(ref[None], z), REFERENCE_COLOR,
                                              point_size=1.5 * self._marker, point_shape="circle",
                                              precision="float32", point_shading="flat")
            error = f"; {float(np.hypot(*(ref[:2] - (x, y)))):.3f} m from the reference"
        else:
            self.server.scene.remove_by_name("/map/run/reference")
            error = ""
        return f", {len(particles)} particles shown{error}"

    def _draw_mapping(self, rec, i: int, z: float) -> str:
        """The map as it was after scan ``i`` (:meth:`~occmap.mapping2d_recording.MappingRecording.occupancy_at`),
        the sensor's path so far and a frame at its pose."""
        occ, k = _pooled(rec.occupancy_at(i), MAX_PLANE_CELLS)
        if occ.size:
            self._draw_image(occupancy_plane(occ, k * rec.resolution, rec.origin, 0.0))
        poses = rec.poses[: i + 1]
        poses = poses[np.isfinite(poses).all(axis=1)]
        self._draw_track("/map/run/path", poses, PATH_COLOR, z)
        if len(poses):
            self._draw_pose("/map/run/pose", poses[-1], z)
        return f", map state {rec.deltas_at(i):,} of {len(rec.delta_steps):,}"

    def _draw_local_map(self, rec, i: int, z: float) -> str:
        """The costmap at step ``i`` as a plane where the window was (the animation's colours), the
        robot's path so far and a frame at its pose, and the tracks as their footprints' outlines
        (confirmed ones darker)."""
        from ..local.replay import cost_rgb
        from ..local.tracking.detection import box_corners

        h, w = rec.costs.shape[1:]
        size = np.array([w, h]) * rec.resolution
        centre = rec.origins[i] + size / 2
        self._draw_image(Plane(cost_rgb(rec.costs[i]), float(size[0]), float(size[1]),
                               np.array([centre[0], centre[1], 0.0])))
        self._draw_track("/map/run/path", rec.poses[: i + 1], ESTIMATE_COLOR, z)
        self._draw_pose("/map/run/pose", rec.poses[i], z)
        t = rec.tracks_at(i)
        for name, sel in (("confirmed", t["confirmed"]), ("tentative", ~t["confirmed"])):
            self.server.scene.remove_by_name(f"/map/run/tracks_{name}")
            if sel.any():
                corners = box_corners(t["x"][sel], t["y"][sel], t["heading"][sel], t["length"][sel], t["width"][sel])
                ends = np.stack([corners, np.roll(corners, -1, axis=1)], axis=2).reshape(-1, 2, 2)
                segments = np.concatenate([ends, np.full((len(ends), 2, 1), z)], axis=2).astype(np.float32)
                self.server.scene.add_line_segments(f"/map/run/tracks_{name}", segments,
                                                    TRACK_COLOR if name == "confirmed" else TENTATIVE_COLOR,
                                                    thickness=3.0, thickness_units="screen")
        return f", {int(t['confirmed'].sum())} confirmed tracks of {len(t['id'])}"

    def _draw_track(self, name: str, poses: np.ndarray, colour, z: float) -> None:
        """The positions of ``poses`` (N, 3) as a line, a little above the map."""
        self.server.scene.remove_by_name(name)
        if len(poses) > 1:
            track = _at_height(poses, z)
            self.server.scene.add_line_segments(name, np.stack([track[:-1], track[1:]], 1), colour,
                                                thickness=2.0, thickness_units="screen")

    def _draw_pose(self, name: str, pose, z: float) -> None:
        """A frame at ``pose`` ``(x, y, theta)``, x ahead."""
        x, y, theta = pose
        self.server.scene.add_frame(name, wxyz=(np.cos(theta / 2), 0.0, 0.0, np.sin(theta / 2)),
                                    position=(x, y, z), axes_length=4 * self._marker, axes_radius=self._marker / 5)

    def _play_loop(self) -> None:
        """Advance a recorded run while "Play" is on, at its recorded pace times the panel's speed
        (:func:`played_to`), to its last step. Moving the slider or the speed while playing plays
        on from there."""
        start = None  # (wall clock, step, speed) the run plays from
        while not self._closing.wait(1.0 / PLAY_RATE):
            with self._lock:
                rec = self.scene.recording if self.scene is not None else None
                if rec is None or not self._play.value or self._loading:
                    start = None
                    continue
                step, speed, now = int(self._step.value), PLAY_SPEEDS[self._speed.value], time.monotonic()
                if step >= len(rec) - 1:
                    self._play.value, start = False, None
                    continue
                if start is None or start[2] != speed or step != self._played:
                    start = (now, step, speed)
                self._played = played_to(rec.stamps, start[1], now - start[0], speed)
                if self._played != step:
                    self._step.value = self._played

    def _draw_slice_plane(self) -> None:
        if SLICES[self._slice_mode.value] == "off":
            self.server.scene.remove_by_name("/map/slice")
            return
        lo, hi = self._bounds
        size = hi[:2] - lo[:2]
        self.server.scene.add_grid("/map/slice", float(size[0]), float(size[1]), plane="xy",
                                   cell_size=1.0, cell_thickness=0.5, cell_color=(170, 190, 230),
                                   section_size=10.0, section_color=(120, 150, 220),
                                   plane_color=(90, 140, 230), plane_opacity=0.1,
                                   position=(*((lo[:2] + hi[:2]) / 2), float(self._z.value)))

    def _drawn_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The box of what is drawn: the occupied boxes or the points where there are some."""
        drawn = self.occupied.voxels if self.occupied is not None else self._points
        if drawn is not None and drawn.count:
            half = drawn.sizes[:, None] / 2
            lo, hi = (drawn.centers - half).min(axis=0), (drawn.centers + half).max(axis=0)
            return lo.astype(np.float64), hi.astype(np.float64)
        return self.scene.bounds

    def _aim_cameras(self) -> None:
        position, center = camera_view(*self._bounds, from_above=self.scene.recording is not None)
        self.server.initial_camera.position = tuple(position)
        self.server.initial_camera.look_at = tuple(center)
        for client in self.server.get_clients().values():
            client.camera.position = position
            client.camera.look_at = center

    # ------------------------------------------------------------------ the panel

    def _build_panel(self) -> None:
        gui = self.server.gui
        self._info = gui.add_markdown("")
        self._colour = gui.add_dropdown("Colour by", COLOURS, initial_value="height")
        self._style = gui.add_dropdown("Draw as", STYLES, initial_value=STYLES[0])
        self._show_free = gui.add_checkbox("Free space", False)
        self._slice_mode = gui.add_dropdown("Slice", tuple(SLICES), initial_value="off")
        self._z = gui.add_slider("Slice z (m)", min=0.0, max=1.0, step=0.01, initial_value=1.0)
        self._nearby = gui.add_dropdown("Maps here", ("",), initial_value="")
        self._path_text = gui.add_text("Open path", "")
        self._open = gui.add_button("Open")
        self._step = gui.add_slider("Step", min=0, max=1, step=1, initial_value=0, visible=False)
        self._play = gui.add_checkbox("Play", False, visible=False)
        self._speed = gui.add_dropdown("Speed", tuple(PLAY_SPEEDS), initial_value="1×", visible=False)
        self._played = 0

        def redraw(_event) -> None:
            with self._lock:
                if self._loading or self.scene is None:  # the panel set by load(), which draws afterwards
                    return
                self._draw_voxels()
                self._draw_free()
                self._draw_points()
                self._draw_slice_plane()

        for control in (self._colour, self._style, self._show_free, self._slice_mode, self._z):
            control.on_update(redraw)

        @self._step.on_update
        def _(_event) -> None:
            with self._lock:
                if not self._loading and self.scene is not None:
                    self._draw_step()

        @self._nearby.on_update
        def _(_event) -> None:
            name = self._nearby.value
            if name and self.scene is not None and name != self.scene.path.name:
                self._path_text.value = str(self.scene.path.parent / name)
                self._open_from_panel(self._path_text.value)

        @self._open.on_click
        def _(_event) -> None:
            self._open_from_panel(self._path_text.value.strip())

    def _update_panel(self) -> None:
        lo, hi = self._bounds
        step = float(self.scene.resolution)
        z_lo, z_hi = float(np.floor(lo[2] / step) * step), float(np.ceil(hi[2] / step) * step)
        self._z.min, self._z.max, self._z.step = z_lo, max(z_hi, z_lo + step), step
        self._z.value = self._z.max
        name = self.scene.path.name
        names = sorted(p.name for p in self.scene.path.parent.iterdir() if p.name != name and viewable(p))
        self._nearby.options = (name, *names[:MAX_LISTED])
        self._nearby.value = self.scene.path.name
        self._path_text.value = str(self.scene.path)
        self._info.content = self._describe()
        rec = self.scene.recording
        self._play.value = False
        self._step.max = max(len(rec) - 1, 1) if rec is not None else 1
        self._step.value = 0
        self._step.visible = self._play.visible = self._speed.visible = rec is not None
        # colours, boxes and slices are for voxels and points; a plane (a 2D map, a run) has none
        solid = self.scene.nodes_at is not None or self.scene.points is not None
        for control in (self._colour, self._slice_mode, self._z):
            control.visible = solid
        self._style.visible = self._show_free.visible = self.scene.nodes_at is not None

    def _describe(self) -> str:
        s = self.scene
        text = f"**{s.path.name}** — {s.kind}: {s.summary}"
        if self.occupied is not None:
            o = self.occupied
            text += (f"\n\n{o.voxels.count:,} occupied boxes drawn at depth {o.depth} "
                     f"({o.leaves:,} occupied leaves)")
        return text


def played_to(stamps: np.ndarray, start: int, elapsed: float, speed: float) -> int:
    """The step a run played from step ``start`` for ``elapsed`` seconds at ``speed`` times its
    recorded pace has reached: the last whose stamp is at most ``stamps[start] + speed · elapsed``
    (a gap in the recording is waited through, as it happened). A run whose stamps do not increase
    has no pace of its own: it plays :data:`PLAY_RATE` steps a second times ``speed``."""
    last = len(stamps) - 1
    if not (np.all(np.diff(stamps) >= 0) and stamps[-1] > stamps[0]):
        return min(start + int(elapsed * PLAY_RATE * speed), last)
    reached = int(np.searchsorted(stamps, stamps[start] + speed * elapsed, side="right")) - 1
    return min(max(reached, start), last)


def _at_height(poses: np.ndarray, z: float) -> np.ndarray:
    """Points (N, 3) float32 at the positions of poses (N, 3) ``(x, y, theta)``, lifted to ``z``."""
    out = np.empty((len(poses), 3), np.float32)
    out[:, :2] = poses[:, :2]
    out[:, 2] = z
    return out


def _pooled(occupancy: np.ndarray, max_side: int) -> tuple[np.ndarray, int]:
    """nav_msgs values (H, W) in blocks of k × k cells (:func:`~occmap.viz._maps.block_max`), the
    smallest k that brings both sides to ``max_side`` at most; and k."""
    k = max(1, -(-max(occupancy.shape) // max_side))
    return (occupancy, 1) if k == 1 else (block_max(occupancy, k), k)
