"""CARMEN laser logs (``.log`` / ``.clf``, plain, gzip, bzip2 or xz) → :class:`~occmap.scan.LaserScan`.

The reader streams the file line by line and never holds more than one line in memory.
Compression is detected from the first bytes (gzip ``1f 8b``, bzip2 ``BZh``, xz ``fd 37 7a 58 5a
00``), whatever the file is called.

Messages read as scans
----------------------
``FLASER`` / ``RLASER`` (front / rear laser, the old fixed-fan form)::

    FLASER n r_1 … r_n x y theta odom_x odom_y odom_theta ipc_timestamp hostname logger_timestamp

``x y theta`` is the pose of the *laser* in the world (for RLASER, the rear laser's own pose,
so its theta already points backwards; nothing is added to it) and becomes ``LaserScan.pose``;
``odom_*`` is the robot's odometry pose and becomes ``LaserScan.odom``. Beam ``i`` points at
``theta + a_i`` (counter-clockwise, right to left) with

* ``a_i = -pi/2 + i*pi/n`` for n = 180 or 360 (1° / 0.5° steps, the last beam one step short of
  +pi/2);
* ``a_i = -pi/2 + i*pi/(n-1)`` for n = 181 or 361 (closed fan, both ends included);
* any other n: the same closed 180° fan, ``-pi/2 + i*pi/(n-1)``, which is what CARMEN's own
  ``carmen_laser_guess_angle_increment`` assumes for a beam count it does not know. (CARMEN
  special-cases 400/401 beams as 0.25° steps starting at -pi/2, i.e. a lopsided 100° fan; we do
  not copy that and treat them like any other count. n = 1 gives the single angle -pi/2.)

``ROBOTLASER1`` (and ``ROBOTLASER2`` … if asked for in ``kinds``), explicit geometry::

    ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode
                n r_1 … r_n n_rem rem_1 … rem_k laser_x laser_y laser_theta
                robot_x robot_y robot_theta tv rv forward_safety side_safety turn_axis
                ipc_timestamp hostname logger_timestamp

Beam ``i`` points at ``laser_theta + start_angle + i*angular_res`` (``fov`` is not used);
``laser_*`` → ``pose``, ``robot_*`` → ``odom``, ``max_range`` → ``max_range`` (unless the caller
overrides it; a line's own ``max_range`` that is not a positive finite number makes the line
malformed, since every reading would then count as "no return" and clear its beam).

Conventions
-----------
* ``pose[2]`` and ``odom[2]`` are wrapped to (-pi, pi] (the csail log reaches 10.9 rad).
* ``odom`` drives backwards where the log's odometry says so. Some logs integrate the odometry
  pose from the unsigned speed: Freiburg 079's raw log (``fr079-raw.clf``) advances every
  ``ODOM``/``FLASER`` odometry pose *forwards* while its ``ODOM`` messages report a negative
  translational velocity ``tv`` (all 320 messages with ``tv < -0.05`` m/s; the corrected log and
  the scans show the robot reversing, up to 2 m at a time). So when the ``ODOM`` messages between
  two scans average ``tv < 0`` and the odometry moved the robot forwards (along its heading) from
  one scan to the next, that step's translation is reversed in the robot's frame (the turn is
  kept) and the odometry from there on is composed from the corrected steps;
  ``CarmenStats.reversed_steps`` counts them. Logs without ``ODOM`` messages, or whose odometry
  already moves backwards when ``tv`` is negative (Intel's has no negative ``tv``), are unchanged.
* ``stamp`` is the logger timestamp (the last field). A line that ends at the hostname (no logger
  timestamp) uses the ipc timestamp instead. Zero or wrapped timestamps are kept as read.
* Maximum range (``LaserScan.max_range``; by that record's convention a reading at or beyond it
  means "no return"): the ``max_range`` argument when given; else, for ROBOTLASER, the line's own
  field; else, for FLASER / RLASER, a ``PARAM`` seen earlier in the log
  (``robot_front_laser_max``, ``laser_front_laser_max_range`` or ``laser_front_laser_max`` for the
  front laser, the same with ``rear`` for the rear one; the last one seen wins); else
  :data:`DEFAULT_MAX_RANGE` = 81.0 m, just below the SICK LMS no-return codes 81.83 / 81.91.
  On the shared logs this marks every no-return code: intel (no PARAM, 81.0 vs 81.83),
  freiburg-079 (PARAM 80.99 vs 81.91), csail (PARAM 50 vs 81.91).
* Readings are otherwise kept as read. Logs whose no-return code lies *below* the maximum range
  (e.g. 32.767 from a 16-bit overflow with an 80 m max) can pass ``no_return_values`` (for example
  :data:`TYPICAL_NO_RETURN`): readings equal to one of them (within 1e-6 m) that lie below the
  scan's max range are set to it; readings at or beyond it already mean "no return" and are kept.
  This is opt-in because 50.0 or 32.767 can also be genuine readings.

Errors and counts
-----------------
A malformed scan line (too few or too many fields, a non-numeric field, a beam count that does not
match the fields, a non-integer or negative count, a non-finite pose) raises
:class:`~occmap.errors.FormatError` naming the file, the line number and what was expected. With
``lenient=True`` it is skipped and counted instead. Comments (``#``), blank lines, ``PARAM``,
``ODOM``, ``SYNC``, ``TRUEPOS``, ``NEFF`` and the other known non-scan messages (and scan kinds not
in ``kinds``) are skipped and counted as "other"; unknown message types are counted apart, by name.
Counts and ``PARAM`` values go into a :class:`CarmenStats` the caller may pass to
:func:`iter_carmen`; :func:`read_carmen` returns them with the scans in a :class:`CarmenLog`.
"""

from __future__ import annotations

import dataclasses
import io
import math
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from .. import checks
from ..errors import FormatError, InvalidArgumentError
from ..geometry.se2 import compose_poses, relative_poses
from ..geometry.so2 import wrap_angle
from ..scan import LaserScan, ScanStack, stack_scans
from ._compression import CORRUPT, open_binary
from ._text import first_non_number, not_a_number, numbers

__all__ = [
    "DEFAULT_MAX_RANGE",
    "TYPICAL_NO_RETURN",
    "CarmenLog",
    "CarmenStats",
    "iter_carmen",
    "read_carmen",
    "flaser_angles",
    "laser_offset",
]

#: Max range (m) for FLASER/RLASER when neither the caller nor a PARAM gives one (SICK LMS).
DEFAULT_MAX_RANGE = 81.0
#: No-return codes seen in CARMEN logs (SICK LMS 81.91 / 81.83, 50 m caps, 16-bit 32.767).
TYPICAL_NO_RETURN = (81.91, 81.83, 50.0, 32.767)

DEFAULT_KINDS = ("FLASER", "RLASER", "ROBOTLASER1")

# Message types that are not scans (or not scans we read); skipped and counted as "other".
_KNOWN_OTHER = frozenset(
    {
        "PARAM", "ODOM", "SYNC", "TRUEPOS", "NEFF", "FLASER", "RLASER", "LASER", "LASER3",
        "LASER4", "RAWLASER1", "RAWLASER2", "RAWLASER3", "RAWLASER4", "ROBOTLASER0",
        "ROBOTLASER1", "ROBOTLASER2", "ROBOTLASER3", "ROBOTLASER4", "GPSNMEA", "NMEAGGA",
        "NMEARMC", "SONAR", "BUMPER", "IMU", "VELOCITY", "BASEVELOCITY", "SCANMARK",
        "POSITIONLASER", "MARKER",
    }
)  # fmt: skip

_MAX_RANGE_PARAMS = {
    "FLASER": ("robot_front_laser_max", "laser_front_laser_max_range", "laser_front_laser_max"),
    "RLASER": ("robot_rear_laser_max", "laser_rear_laser_max_range", "laser_rear_laser_max"),
}

_MAX_KEPT_ERRORS = 100
_EMPTY = np.zeros(0)


@dataclass
class CarmenStats:
    """What :func:`iter_carmen` saw; filled in as the generator runs (final once it is exhausted).

    Attributes
    ----------
    lines : int
        Lines read.
    scans : int
        Scans yielded.
    skipped_malformed : int
        Malformed scan lines skipped (``lenient=True`` only; otherwise the first one raises).
    skipped_other : int
        Comments and known non-scan messages (PARAM, ODOM, SYNC, TRUEPOS, NEFF, ...), including
        scan kinds not asked for. Blank lines are not counted.
    skipped_unknown : int
        Lines whose message type the reader does not know; ``unknown_types`` counts them by name.
    skipped_decimated : int
        Scans of the selected kinds passed over by ``every`` (not parsed, so not validated).
    params : dict[str, str]
        ``PARAM name value``: the value as written (the last one wins when a name repeats).
    assumed_max_range : int
        FLASER / RLASER scans given :data:`DEFAULT_MAX_RANGE` because neither the caller nor a
        ``PARAM`` of the log said what their laser's maximum range is.
    guessed_angles : int
        FLASER / RLASER scans whose beam count (not 180, 181, 360 or 361) does not say their
        angular step, given the closed 180° fan CARMEN guesses.
    reversed_steps : int
        Scan-to-scan odometry steps driven backwards because the ``ODOM`` messages between the two
        scans report a negative speed while the odometry pose moved forwards (module docstring).
    errors : list[FormatError]
        The first 100 malformed-line errors met in lenient mode, for reporting.
    """

    lines: int = 0
    scans: int = 0
    skipped_malformed: int = 0
    skipped_other: int = 0
    skipped_unknown: int = 0
    skipped_decimated: int = 0
    unknown_types: dict[str, int] = field(default_factory=dict)
    params: dict[str, str] = field(default_factory=dict)
    assumed_max_range: int = 0
    guessed_angles: int = 0
    reversed_steps: int = 0
    errors: list[FormatError] = field(default_factory=list)


@dataclass
class CarmenLog:
    """A whole CARMEN log read by :func:`read_carmen`: the scans in file order and the counts."""

    path: str
    scans: list[LaserScan]
    stats: CarmenStats

    @property
    def skipped_malformed(self) -> int:
        return self.stats.skipped_malformed

    @property
    def skipped_other(self) -> int:
        return self.stats.skipped_other

    @property
    def skipped_unknown(self) -> int:
        return self.stats.skipped_unknown

    @property
    def params(self) -> dict[str, str]:
        return self.stats.params

    def __len__(self) -> int:
        return len(self.scans)

    def __repr__(self) -> str:
        st = self.stats
        return (
            f"CarmenLog({self.path!r}, {len(self.scans)} scans, skipped_malformed="
            f"{st.skipped_malformed}, skipped_other={st.skipped_other}, "
            f"skipped_unknown={st.skipped_unknown}, {len(st.params)} params)"
        )

    def __iter__(self) -> Iterator[LaserScan]:
        return iter(self.scans)

    def __getitem__(self, index):
        return self.scans[index]

    def stack(self) -> ScanStack:
        """All scans as arrays; see :func:`occmap.scan.stack_scans`."""
        return stack_scans(self.scans)

    def laser_offset(self, laser: str = "front") -> tuple[float, float, float]:
        """:func:`laser_offset` of this log's PARAMs."""
        return laser_offset(self.params, laser, self.path)


def laser_offset(params: dict[str, str], laser: str = "front", path="CARMEN log") -> tuple[float, float, float]:
    """Pose ``(x, y, theta)`` (m, rad) of the ``"front"`` or ``"rear"`` laser in the robot frame,
    from CARMEN's ``PARAM robot_<laser>laser_offset`` (forward), ``..._side_offset`` (left) and
    ``..._angular_offset`` in ``params`` (:attr:`CarmenStats.params`); a missing one is 0. A FLASER
    line's ``x y theta`` is this laser's pose, its ``odom_*`` the robot's (Freiburg 079's raw log:
    ``robot_frontlaser_offset -0.04``). A value that is not a finite number raises
    :class:`~occmap.errors.FormatError` naming ``path`` and the PARAM."""
    if laser not in ("front", "rear"):
        raise InvalidArgumentError(f"laser must be 'front' or 'rear', got {laser!r}")
    out = []
    for part in ("offset", "side_offset", "angular_offset"):
        name = f"robot_{laser}laser_{part}"
        text = params.get(name, "0")
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise FormatError(path, f"PARAM {name} is {text!r}, not a finite number")
        out.append(value)
    return tuple(out)


def flaser_angles(n: int) -> np.ndarray:
    """Beam angles (radians, relative to the laser heading) of an ``n``-beam FLASER/RLASER scan,
    by the rules in the module docstring. Returns a new float64 array."""
    n = checks.count("beam count n", n, minimum=0)
    i = np.arange(n, dtype=np.float64)
    if n in (180, 360):
        return -0.5 * np.pi + i * (np.pi / n)
    if n <= 1:
        return np.full(n, -0.5 * np.pi)
    return -0.5 * np.pi + i * (np.pi / (n - 1))


def _open_text(path) -> io.TextIOBase:
    # latin-1 never fails to decode; stray bytes then fail as non-numeric fields, with a line number
    return io.TextIOWrapper(open_binary(path), encoding="latin-1", newline=None)


def _numbers(text: str) -> np.ndarray:
    """The numbers of a message body; empty when a token is not a number (the caller, finding
    the count wrong, names the bad field)."""
    vals = numbers(text)
    return _EMPTY if vals is None else vals


def _is_count(value) -> bool:
    """Whether a parsed field is a whole number >= 0 (NaN and inf are not)."""
    return value >= 0 and float(value).is_integer()


def _split_tail(rest: str):
    """Split ``... ipc_timestamp hostname logger_timestamp`` off a message body.

    Returns ``(numeric_text, logger_timestamp or None)``; ``None`` when the line ends at the
    hostname. Raises ValueError when the line is too short to hold a hostname."""
    parts = rest.rsplit(None, 2)
    if len(parts) < 3:
        raise ValueError
    try:
        return parts[0], float(parts[2])
    except ValueError:
        # no logger timestamp: the last token is the hostname
        head, _host = rest.rsplit(None, 1)
        return head, None


class _Parser:
    """Per-file state: angle caches and PARAM-derived max ranges."""

    def __init__(self, path, max_range, no_return_values, stats):
        self.path = path
        self.max_range = None if max_range is None else float(max_range)
        self.no_return = tuple(float(v) for v in (no_return_values or ()))
        self.stats = stats
        self._angle_cache: dict = {}
        self._param_max: dict[str, float] = {}
        # signed odometry: the ODOM speeds since the last scan, that scan's odometry as read and as corrected
        self._tv_sum = 0.0
        self._tv_n = 0
        self._odom_read = None
        self._odom_signed = None

    # -- helpers -------------------------------------------------------------------------------
    def _angles(self, key, make) -> np.ndarray:
        a = self._angle_cache.get(key)
        if a is None:
            a = make()
            a.flags.writeable = False
            self._angle_cache[key] = a
        return a

    def param(self, name: str, value: str) -> None:
        self.stats.params[name] = value
        for kind, names in _MAX_RANGE_PARAMS.items():
            if name in names:
                try:
                    v = float(value)
                except ValueError:
                    continue
                if v > 0 and math.isfinite(v):
                    self._param_max[kind] = v

    def odom_speed(self, line: str) -> None:
        """Note the translational velocity ``tv`` of an ``ODOM x y theta tv rv accel ...`` line (a
        line without a finite one is left out: ODOM lines are not validated)."""
        p = line.split(None, 5)
        if len(p) >= 5:
            try:
                tv = float(p[4])
            except ValueError:
                return
            if math.isfinite(tv):
                self._tv_sum += tv
                self._tv_n += 1

    def signed_odometry(self, scan: LaserScan) -> LaserScan:
        """``scan`` with its odometry step from the previous scan reversed when the ODOM speeds
        between them say the robot drove backwards but the step goes forwards (module docstring)."""
        read = scan.odom
        if read is None:
            return scan
        backwards = self._tv_n > 0 and self._tv_sum < 0.0
        self._tv_sum, self._tv_n = 0.0, 0
        prev_read, prev_signed = self._odom_read, self._odom_signed
        self._odom_read = read
        if prev_read is None:
            self._odom_signed = read
            return scan
        step = relative_poses(prev_read, read)
        if backwards and step[0] > 0.0:
            step[:2] = -step[:2]
            self.stats.reversed_steps += 1
        elif np.array_equal(prev_read, prev_signed):
            self._odom_signed = read  # nothing corrected so far: keep the log's numbers exactly
            return scan
        signed = compose_poses(prev_signed, step)
        signed[2] = wrap_angle(signed[2])
        self._odom_signed = signed
        return dataclasses.replace(scan, odom=signed)

    def _fail(self, lineno, what):
        return FormatError(self.path, what, line=lineno)

    def _finish_ranges(self, ranges, max_range):
        for v in self.no_return:
            if v < max_range:
                ranges[np.abs(ranges - v) <= 1e-6] = max_range

    def _pose(self, vals, at, lineno, kind, what):
        x, y, t = vals[at], vals[at + 1], vals[at + 2]
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(t)):
            raise self._fail(lineno, f"{kind}: {what} must be finite, got ({x}, {y}, {t})")
        return np.array((x, y, float(wrap_angle(t))))

    def _bad_numbers(self, lineno, kind, text, layout):
        bad = first_non_number(text)
        if bad is not None:
            k, tok = bad  # field 1 is the message name
            return not_a_number(self.path, lineno, k + 2, tok, f"{kind} {layout}")
        return None

    # -- messages ------------------------------------------------------------------------------
    def flaser(self, kind: str, rest: str, lineno: int) -> LaserScan:
        layout = "n r_1..r_n x y theta odom_x odom_y odom_theta ipc_timestamp hostname logger_timestamp"
        try:
            text, logger = _split_tail(rest)
        except ValueError:
            raise self._fail(lineno, f"{kind}: line too short, expected {layout}") from None
        vals = _numbers(text)
        if vals.size == 0:
            err = self._bad_numbers(lineno, kind, text, layout)
            raise err or self._fail(lineno, f"{kind}: no beam count, expected {layout}")
        n_f = vals[0]
        if not _is_count(n_f):
            raise self._fail(lineno, f"{kind}: beam count {n_f!r} is not a non-negative integer")
        n = int(n_f)
        if vals.size != n + 8:
            err = self._bad_numbers(lineno, kind, text, layout)
            if err is not None:
                raise err
            have = len(text.split()) - 1
            raise self._fail(
                lineno,
                f"{kind}: beam count n = {n} needs {n + 7} numbers between n and the hostname "
                f"(n ranges, x y theta, odom_x odom_y odom_theta, ipc_timestamp), the line has "
                f"{have} (expected {layout})",
            )
        pose = self._pose(vals, n + 1, lineno, kind, "x y theta")
        odom = self._pose(vals, n + 4, lineno, kind, "odom_x odom_y odom_theta")
        stamp = float(vals[n + 7]) if logger is None else logger
        if self.max_range is not None:
            mr = self.max_range
        else:
            mr = self._param_max.get(kind)
            if mr is None:
                mr = DEFAULT_MAX_RANGE
                self.stats.assumed_max_range += 1
        ranges = vals[1 : n + 1]
        if self.no_return:
            self._finish_ranges(ranges, mr)
        angles = self._angles(n, lambda: flaser_angles(n))
        if n not in (180, 181, 360, 361):
            self.stats.guessed_angles += 1
        return LaserScan(pose=pose, ranges=ranges, angles=angles, max_range=mr, stamp=stamp, odom=odom)

    def robotlaser(self, kind: str, rest: str, lineno: int) -> LaserScan:
        layout = (
            "laser_type start_angle fov angular_res max_range accuracy remission_mode n r_1..r_n "
            "n_rem rem_1..rem_k laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv "
            "forward_safety side_safety turn_axis ipc_timestamp hostname logger_timestamp"
        )
        try:
            text, logger = _split_tail(rest)
        except ValueError:
            raise self._fail(lineno, f"{kind}: line too short, expected {layout}") from None
        vals = _numbers(text)
        size = vals.size
        problem = None
        if size < 8:
            problem = "line too short for the laser configuration and beam count"
        else:
            n_f = vals[7]
            if not _is_count(n_f):
                raise self._fail(lineno, f"{kind}: beam count {n_f!r} is not a non-negative integer")
            n = int(n_f)
            if size < n + 9:
                problem = f"beam count n = {n} runs past the end of the line"
            else:
                k_f = vals[n + 8]
                if not _is_count(k_f):
                    raise self._fail(
                        lineno, f"{kind}: remission count {k_f!r} is not a non-negative integer"
                    )
                k = int(k_f)
                if size != n + k + 21:
                    problem = (
                        f"with n = {n} beams and {k} remissions the line needs {n + k + 21} "
                        f"numbers before the hostname, it has {size}"
                    )
        if problem is not None:
            err = self._bad_numbers(lineno, kind, text, layout)
            raise err or self._fail(lineno, f"{kind}: {problem} (expected {layout})")
        start, res = float(vals[1]), float(vals[3])
        if not (math.isfinite(start) and math.isfinite(res)):
            raise self._fail(lineno, f"{kind}: start_angle and angular_res must be finite")
        at = n + k + 9
        pose = self._pose(vals, at, lineno, kind, "laser_x laser_y laser_theta")
        odom = self._pose(vals, at + 3, lineno, kind, "robot_x robot_y robot_theta")
        stamp = float(vals[size - 1]) if logger is None else logger
        mr = self.max_range if self.max_range is not None else float(vals[4])
        if not (mr > 0 and math.isfinite(mr)):
            # a reading at or beyond it means "no return": -1 would clear every beam
            raise self._fail(lineno, f"{kind}: max_range {mr!r} must be a positive finite number")
        ranges = vals[8 : n + 8]
        if self.no_return:
            self._finish_ranges(ranges, mr)
        angles = self._angles(
            ("R", start, res, n), lambda: start + np.arange(n, dtype=np.float64) * res
        )
        return LaserScan(pose=pose, ranges=ranges, angles=angles, max_range=mr, stamp=stamp, odom=odom)


def iter_carmen(
    path,
    kinds: Iterable[str] = DEFAULT_KINDS,
    lenient: bool = False,
    every: int = 1,
    *,
    max_range: float | None = None,
    no_return_values: Iterable[float] | None = None,
    stats: CarmenStats | None = None,
) -> Iterator[LaserScan]:
    """Stream the scans of a CARMEN log as :class:`~occmap.scan.LaserScan` records, in file order.

    Parameters
    ----------
    path : str or os.PathLike
        The log; plain text, gzip, bzip2 or xz (detected from the first bytes).
    kinds : iterable of str
        Message types to read as scans: any of ``FLASER``, ``RLASER``, ``ROBOTLASER1`` …
        ``ROBOTLASER4``. Others are skipped and counted in ``stats.skipped_other``.
    lenient : bool
        Skip and count malformed scan lines instead of raising :class:`FormatError`.
    every : int
        Keep the 1st, (1+every)th, ... message of the selected kinds; the ones in between are
        counted in ``stats.skipped_decimated`` and not parsed (so not validated).
    max_range : float, optional
        Maximum range for every scan. Default: inferred (see the module docstring).
    no_return_values : iterable of float, optional
        Readings equal to one of these (within 1e-6 m) and below the scan's max range are set to
        it ("no return"). Default: none; :data:`TYPICAL_NO_RETURN` holds the common codes.
    stats : CarmenStats, optional
        Filled in as the generator runs: counts, PARAM values and (lenient) the errors met.

    Raises
    ------
    FormatError
        A malformed scan line (unless ``lenient``), or a corrupt compressed stream.
    InvalidArgumentError
        A bad ``kinds``, ``every`` or ``max_range`` (raised at the call, before any reading).
    """
    every = checks.count("every", every)
    if max_range is not None:
        max_range = checks.positive("max_range", max_range, "metres")
    if isinstance(kinds, str):
        kinds = (kinds,)
    wanted = {str(k).upper() for k in kinds}
    for k in wanted:
        if k not in ("FLASER", "RLASER") and not (k.startswith("ROBOTLASER") and k[10:].isdigit()):
            raise InvalidArgumentError(
                f"unsupported scan kind {k!r}: expected FLASER, RLASER or ROBOTLASER1..ROBOTLASER4"
            )
    if stats is None:
        stats = CarmenStats()
    path_str = os.fspath(path)
    parser = _Parser(path_str, max_range, no_return_values, stats)
    # arguments are checked now; the file is opened on the first next()
    return _scan_lines(path_str, wanted, lenient, every, parser, stats)


def _scan_lines(path_str, wanted, lenient, every, parser, stats) -> Iterator[LaserScan]:
    seen = 0
    f = _open_text(path_str)
    lineno = 0
    try:
        for line in f:
            lineno += 1
            stats.lines = lineno
            parts = line.split(None, 1)
            if not parts:
                continue
            kind = parts[0]
            if kind in wanted:
                seen += 1
                if (seen - 1) % every:
                    stats.skipped_decimated += 1
                    continue
                rest = parts[1] if len(parts) > 1 else ""
                try:
                    if kind.startswith("ROBOTLASER"):
                        scan = parser.robotlaser(kind, rest, lineno)
                    else:
                        scan = parser.flaser(kind, rest, lineno)
                except FormatError as err:
                    if not lenient:
                        raise
                    stats.skipped_malformed += 1
                    if len(stats.errors) < _MAX_KEPT_ERRORS:
                        stats.errors.append(err)
                    continue
                stats.scans += 1
                yield parser.signed_odometry(scan)
            elif kind[0] == "#":
                stats.skipped_other += 1
            elif kind == "PARAM":
                stats.skipped_other += 1
                p = line.split()
                if len(p) >= 3:
                    parser.param(p[1], p[2])
            elif kind in _KNOWN_OTHER:
                stats.skipped_other += 1
                if kind == "ODOM":
                    parser.odom_speed(line)
            else:
                stats.skipped_unknown += 1
                stats.unknown_types[kind] = stats.unknown_types.get(kind, 0) + 1
    except CORRUPT as exc:
        raise FormatError(
            path_str, f"compressed stream is corrupt or ends early ({exc})", line=lineno + 1
        ) from exc
    finally:
        f.close()


def read_carmen(path, *args, **kwargs) -> CarmenLog:
    """Read a whole CARMEN log: :func:`iter_carmen` collected into a :class:`CarmenLog`
    (``.scans``, ``.skipped_malformed``, ``.skipped_other``, ``.skipped_unknown``, ``.params``,
    ``.stats``, ``.stack()``). Same arguments (but ``stats``, which the log holds) and errors as
    :func:`iter_carmen`."""
    stats = CarmenStats()
    scans = list(iter_carmen(path, *args, stats=stats, **kwargs))
    return CarmenLog(path=os.fspath(path), scans=scans, stats=stats)
