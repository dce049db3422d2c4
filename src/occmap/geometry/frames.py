"""A time-stamped tree of coordinate frames with ROS tf2 semantics.

Conventions
-----------
- A link stores ``T_parent_child``: it maps child coordinates into the parent frame,
  ``p_parent = T_parent_child @ p_child``. ``lookup(target, source)`` returns ``T_target_source``.
- Stamps are float seconds. Between two samples of a link the translation is interpolated linearly
  and the rotation by slerp along the shorter arc; a stamp equal to a sample's stamp returns that
  sample, not an interpolation. Nothing is extrapolated: a stamp before a link's first or after its last sample
  raises :class:`~occmap.errors.ExtrapolationError`, so a link holding one sample can be looked up
  only at exactly its stamp (as in tf2).
- Static links hold for all time.
- ``stamp=None`` in a lookup means the latest common time of the path (tf2's
  ``getLatestCommonTime``): the smallest newest-stamp over the dynamic links on the path.

Differences from tf2, chosen for simplicity:

- A frame has one parent for all time. Setting a link to an existing child with another parent
  re-parents the child and clears that link's history; so does switching a link between static and
  dynamic.
- A sample at a stamp the link already holds replaces the stored one (tf2 ignores it with a
  ``TF_REPEATED_DATA`` warning).
- Samples older than the link's newest stamp minus ``cache_time`` are dropped, also when they
  arrive late (tf2 rejects those too).

Storage is one set of NumPy arrays per link (stamps ``(n,)``, translations ``(n, 3)``, unit
quaternions ``(n, 4)`` scalar first), grown by capacity doubling; appending in time order is
amortised O(1), out-of-order samples are merged in with ``np.searchsorted``.
"""

from __future__ import annotations

import numpy as np

from .. import checks
from ..errors import (
    ConnectivityError,
    ExtrapolationError,
    FrameLoopError,
    InvalidArgumentError,
    NonFiniteError,
    ShapeError,
    TransformError,
    UnknownFrameError,
)
from ._kernels import interpolate_samples
from .quaternion import quat_conjugate, quat_multiply, quat_rotate
from .se3 import SE3

__all__ = ["FrameTree"]

_MIN_CAPACITY = 16


class _Link:
    """The samples of one ``parent -> child`` link, sorted by stamp.

    The live samples are ``buffer[start:end]``; dropping old samples advances ``start``, and the
    buffers are compacted or doubled only when ``end`` reaches their capacity.
    """

    __slots__ = ("parent", "child", "static", "_stamps", "_trans", "_quats", "_start", "_end")

    def __init__(self, parent: str, child: str, static: bool, capacity: int):
        self.parent = parent
        self.child = child
        self.static = static
        self._stamps = np.empty(capacity)
        self._trans = np.empty((capacity, 3))
        self._quats = np.empty((capacity, 4))
        self._start = 0
        self._end = 0

    def __len__(self) -> int:
        return self._end - self._start

    @property
    def stamps(self) -> np.ndarray:
        return self._stamps[self._start : self._end]

    @property
    def translations(self) -> np.ndarray:
        return self._trans[self._start : self._end]

    @property
    def quaternions(self) -> np.ndarray:
        return self._quats[self._start : self._end]

    def _reserve(self, extra: int) -> None:
        """Make room for ``extra`` samples after ``end``."""
        cap = self._stamps.shape[0]
        if self._end + extra <= cap:
            return
        n = len(self)
        needed = n + extra
        if needed <= cap // 2:
            # Sliding the samples to the front frees at least cap/2 slots, so compaction too is
            # amortised O(1) per appended sample.
            stamps, trans, quats = self._stamps, self._trans, self._quats
        else:
            cap = max(2 * needed, _MIN_CAPACITY)
            stamps, trans, quats = np.empty(cap), np.empty((cap, 3)), np.empty((cap, 4))
        stamps[:n] = self.stamps
        trans[:n] = self.translations
        quats[:n] = self.quaternions
        self._stamps, self._trans, self._quats = stamps, trans, quats
        self._start, self._end = 0, n

    def append(self, stamps: np.ndarray, trans: np.ndarray, quats: np.ndarray) -> None:
        """Append samples whose stamps are sorted and later than every stored stamp."""
        k = stamps.shape[0]
        self._reserve(k)
        self._stamps[self._end : self._end + k] = stamps
        self._trans[self._end : self._end + k] = trans
        self._quats[self._end : self._end + k] = quats
        self._end += k

    def insert(self, stamps: np.ndarray, trans: np.ndarray, quats: np.ndarray) -> None:
        """Insert samples with sorted, distinct stamps anywhere in time; equal stamps replace."""
        old = self.stamps
        n = old.shape[0]
        pos = np.searchsorted(old, stamps, side="left")
        hit = pos < n
        hit[hit] = old[pos[hit]] == stamps[hit]
        if hit.any():
            self.translations[pos[hit]] = trans[hit]
            self.quaternions[pos[hit]] = quats[hit]
            keep = ~hit
            stamps, trans, quats, pos = stamps[keep], trans[keep], quats[keep], pos[keep]
        k = stamps.shape[0]
        if k == 0:
            return
        if n == 0 or stamps[0] > old[-1]:
            self.append(stamps, trans, quats)
            return
        m = n + k
        new_at = pos + np.arange(k)  # strictly increasing: the merged slots of the new samples
        old_at = np.ones(m, dtype=bool)
        old_at[new_at] = False
        cap = max(self._stamps.shape[0], 2 * m, _MIN_CAPACITY)
        merged = np.empty(cap), np.empty((cap, 3)), np.empty((cap, 4))
        for buf, existing, new in zip(merged, (old, self.translations, self.quaternions), (stamps, trans, quats)):
            buf[:m][new_at] = new
            buf[:m][old_at] = existing
        self._stamps, self._trans, self._quats = merged
        self._start, self._end = 0, m

    def prune(self, cache_time: float, max_history: int | None) -> None:
        """Drop samples older than ``newest - cache_time`` and all but the newest ``max_history``."""
        stamps = self.stamps
        self._start += int(np.searchsorted(stamps, stamps[-1] - cache_time, side="left"))
        if max_history is not None and len(self) > max_history:
            self._start = self._end - max_history

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Interpolate ``(quaternions (M, 4), translations (M, 3))`` at stamps ``t`` (M,).

        A static or one-sample link returns arrays of length 1, which broadcast. The caller has
        checked that every stamp lies within the stored range.
        """
        if self.static or len(self) == 1:
            return self.quaternions[:1], self.translations[:1]
        q, tr = np.empty((t.shape[0], 4)), np.empty((t.shape[0], 3))
        interpolate_samples(self.stamps, self.translations, self.quaternions, t, q, tr)
        return q, tr


class FrameTree:
    """A tree of named frames joined by time-stamped rigid transforms (ROS tf2's ``BufferCore``).

    Parameters
    ----------
    cache_time:
        Seconds of history kept per link: samples older than that link's newest stamp minus
        ``cache_time`` are dropped (tf2's default cache is 10 s).
    max_history:
        If given, also keep at most this many samples per link (the newest ones).

    Example::

        tree = FrameTree()
        tree.set_transform("map", "odom", np.eye(4), static=True)
        tree.set_transform("odom", "base_link", poses, stamps)  # poses (N, 4, 4), stamps (N,)
        T_map_base = tree.lookup("map", "base_link", 1.25)       # SE3: base_link -> map coordinates
    """

    def __init__(self, cache_time: float = 10.0, max_history: int | None = None):
        self.cache_time = checks.positive("cache_time", cache_time, "seconds")
        self.max_history = None if max_history is None else checks.count("max_history", max_history)
        self._links: dict[str, _Link] = {}  # keyed by child frame
        self._frames: dict[str, None] = {}  # every known frame, in order of first appearance

    # ------------------------------------------------------------------ structure

    @property
    def frames(self) -> list[str]:
        """Names of all frames, in the order they first appeared."""
        return list(self._frames)

    def __contains__(self, frame: object) -> bool:
        return frame in self._frames

    def parent(self, frame: str) -> str | None:
        """The parent of ``frame``, or None if it is a root."""
        self._check_known(frame)
        link = self._links.get(frame)
        return None if link is None else link.parent

    def __repr__(self) -> str:
        head = f"FrameTree(cache_time={self.cache_time!r}, max_history={self.max_history!r}"
        if not self._frames:
            return head + ", no frames)"
        children: dict[str, list[str]] = {}
        for child, link in self._links.items():
            children.setdefault(link.parent, []).append(child)
        lines = [head + f", {len(self._frames)} frames)"]

        def walk(frame: str, indent: str, branch: str, last: bool) -> None:
            link = self._links.get(frame)
            lines.append(f"{indent}{branch}{frame}{'' if link is None else '  ' + _describe(link)}")
            kids = children.get(frame, [])
            deeper = indent + ("" if not branch else "    " if last else "│   ")
            for i, kid in enumerate(kids):
                is_last = i == len(kids) - 1
                walk(kid, deeper, "└── " if is_last else "├── ", is_last)

        for root in (f for f in self._frames if f not in self._links):
            walk(root, "  ", "", True)
        return "\n".join(lines)

    # ------------------------------------------------------------------ writing

    def set_transform(self, parent: str, child: str, T, stamp=None, static: bool = False) -> None:
        """Store ``T_parent_child`` (maps child coordinates into ``parent``) at ``stamp`` seconds.

        ``T`` is a ``(4, 4)`` rigid transform or an :class:`SE3`; with a scalar ``stamp`` it adds
        one sample. A batch ``T`` of shape ``(N, 4, 4)`` (or an SE3 of shape ``(N,)``) with
        ``stamp`` of shape ``(N,)`` adds N samples at once, in any order. ``static=True`` stores
        one transform valid at all times and ignores ``stamp``.

        Replaces the link's history when the child gets a new parent or the link switches between
        static and dynamic; a sample at an already stored stamp replaces that sample.

        Raises
        ------
        FrameLoopError
            ``parent == child`` or ``child`` is an ancestor of ``parent``.
        NotARotationError, NonFiniteError, ShapeError
            ``T`` is not a rigid transform of a valid shape, or the stamps are not finite or
            do not match the batch.
        InvalidArgumentError
            A frame name is not a non-empty string, or a dynamic link has no stamp.
        """
        for name in (parent, child):
            if not isinstance(name, str) or not name:
                raise InvalidArgumentError(f"frame names must be non-empty strings, got {name!r}")
        if parent == child:
            raise FrameLoopError(f"cannot link frame {child!r} to itself")
        ancestor: str | None = parent
        while ancestor is not None:
            if ancestor == child:
                raise FrameLoopError(
                    f"setting {parent!r} -> {child!r} would close a loop: {child!r} is already an "
                    f"ancestor of {parent!r} ({' -> '.join(self._chain(parent)[::-1])})"
                )
            link = self._links.get(ancestor)
            ancestor = None if link is None else link.parent

        pose = T if isinstance(T, SE3) else SE3.from_matrix(_matrix_arg(T))
        trans = np.asarray(pose.translation, dtype=np.float64)
        quats = np.asarray(pose.rotation.as_quat(), dtype=np.float64)
        if trans.ndim not in (1, 2):
            raise ShapeError(f"T must be one transform (4, 4) or a batch (N, 4, 4), got batch shape {trans.shape[:-1]}")
        batched = trans.ndim == 2
        if batched and trans.shape[0] == 0:
            raise ShapeError("T is an empty batch; give at least one transform")

        if static:
            if batched and trans.shape[0] != 1:
                raise ShapeError(f"a static link takes one transform, got a batch of {trans.shape[0]}")
            stamps = np.zeros(1)
            trans, quats = trans.reshape(1, 3), quats.reshape(1, 4)
        else:
            if stamp is None:
                raise InvalidArgumentError(f"link {parent!r} -> {child!r} is dynamic and needs a stamp (or pass static=True)")
            stamps = np.asarray(stamp, dtype=np.float64)
            want = trans.shape[:-1]
            if stamps.shape != want:
                raise ShapeError(f"stamp must have shape {want} to match T, got {stamps.shape}")
            if not np.isfinite(stamps).all():
                raise NonFiniteError(f"stamps of link {parent!r} -> {child!r} must be finite, got {stamp!r}")
            stamps, trans, quats = stamps.reshape(-1), trans.reshape(-1, 3), quats.reshape(-1, 4)

        link = self._links.get(child)
        if link is None or link.parent != parent or link.static != static or static:
            link = _Link(parent, child, static, 1 if static else max(_MIN_CAPACITY, 2 * stamps.shape[0]))
            self._links[child] = link
        self._frames.setdefault(parent)
        self._frames.setdefault(child)

        if stamps.shape[0] > 1 and not (np.diff(stamps) > 0).all():
            order = np.argsort(stamps, kind="stable")
            stamps, trans, quats = stamps[order], trans[order], quats[order]
            # Of equal stamps the one given last wins, as with one-by-one calls.
            last = np.append(stamps[1:] != stamps[:-1], True)
            stamps, trans, quats = stamps[last], trans[last], quats[last]
        if len(link) == 0 or stamps[0] > link.stamps[-1]:
            link.append(stamps, trans, quats)
        else:
            link.insert(stamps, trans, quats)
        if not static:
            link.prune(self.cache_time, self.max_history)

    # ------------------------------------------------------------------ reading

    def lookup(self, target: str, source: str, stamp=None) -> SE3:
        """``T_target_source`` at ``stamp`` seconds: maps ``source`` coordinates into ``target``.

        ``stamp`` is a float, an array of stamps (the result is an SE3 of the same shape), or None
        for the latest common time of the path (any time if every link on it is static).

        Raises
        ------
        UnknownFrameError
            A frame was never set.
        ConnectivityError
            The frames lie in different trees.
        ExtrapolationError
            A stamp lies outside the samples of a dynamic link on the path; the message names the
            link, the requested time, and whether it is before the first or after the last sample.
        """
        up, down, t, shape = self._resolve(target, source, stamp)
        q_ls, t_ls = self._compose(up, t)  # T_lca_source
        q_lt, t_lt = self._compose(down, t)  # T_lca_target
        if q_ls is None:
            q_ls, t_ls = np.array([[1.0, 0.0, 0.0, 0.0]]), np.zeros((1, 3))
        if q_lt is not None:
            # T_target_source = T_lca_target⁻¹ T_lca_source
            q_inv = quat_conjugate(q_lt)
            q_ls = quat_multiply(q_inv, q_ls)
            t_ls = quat_rotate(q_inv, t_ls - t_lt)
        m = t.shape[0]
        if q_ls.shape[0] != m or t_ls.shape[0] != m:  # only static or one-sample links on the path
            q_ls, t_ls = np.broadcast_to(q_ls, (m, 4)), np.broadcast_to(t_ls, (m, 3))
        return SE3.from_quat(q_ls.reshape(shape + (4,)), t_ls.reshape(shape + (3,)))

    def can_transform(self, target: str, source: str, stamp=None) -> bool:
        """Whether :meth:`lookup` with the same arguments would succeed (checks only, no maths).

        Non-finite stamps still raise :class:`~occmap.errors.NonFiniteError`.
        """
        try:
            self._resolve(target, source, stamp)
        except TransformError:
            return False
        return True

    def transform_points(self, target: str, source: str, points, stamp=None) -> np.ndarray:
        """Map ``points`` (..., 3) given in ``source`` into ``target`` at ``stamp`` seconds.

        Equivalent to ``lookup(target, source, stamp).apply(points)``, with its broadcasting.
        """
        return self.lookup(target, source, stamp).apply(points)

    def latest_common_time(self, target: str, source: str) -> float | None:
        """Newest stamp at which every dynamic link between the frames has data (tf2's
        ``getLatestCommonTime``), or None when the path holds only static links."""
        return _latest_common_time(*self._path(target, source))

    # ------------------------------------------------------------------ internals

    def _check_known(self, frame: str) -> None:
        if frame not in self._frames:
            known = ", ".join(map(repr, self._frames)) or "none"
            raise UnknownFrameError(f"frame {frame!r} does not exist (known frames: {known})")

    def _chain(self, frame: str) -> list[str]:
        """``frame``, its parent, ..., up to its root."""
        chain = [frame]
        while (link := self._links.get(chain[-1])) is not None:
            chain.append(link.parent)
        return chain

    def _path(self, target: str, source: str) -> tuple[list[_Link], list[_Link]]:
        """Links from ``source`` up to the lowest common ancestor, and from ``target`` up to it."""
        self._check_known(target)
        self._check_known(source)
        up, down = self._chain(source), self._chain(target)
        if up[-1] != down[-1]:
            raise ConnectivityError(
                f"frames {target!r} and {source!r} are not connected: {target!r} is in the tree "
                f"rooted at {down[-1]!r}, {source!r} in the tree rooted at {up[-1]!r}"
            )
        while len(up) > 1 and len(down) > 1 and up[-2] == down[-2]:
            up.pop()
            down.pop()
        return [self._links[f] for f in up[:-1]], [self._links[f] for f in down[:-1]]

    def _resolve(self, target, source, stamp) -> tuple[list[_Link], list[_Link], np.ndarray, tuple[int, ...]]:
        """Validate a lookup: the two paths, the flat stamps (M,), and the result shape."""
        up, down = self._path(target, source)
        if stamp is None:
            latest = _latest_common_time(up, down)
            t = np.array([0.0 if latest is None else latest])
            shape: tuple[int, ...] = ()
        else:
            t = np.asarray(stamp, dtype=np.float64)
            shape = t.shape
            t = t.reshape(-1)
            if not np.isfinite(t).all():
                raise NonFiniteError(f"lookup stamps must be finite, got {stamp!r}")
        if t.shape[0]:
            for link in (*up, *down):
                if not link.static:
                    _check_range(link, t, target, source)
        return up, down, t, shape

    @staticmethod
    def _compose(links: list[_Link], t: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Quaternions and translations of ``T_top_bottom`` along ``links`` (bottom first)."""
        q = tr = None
        for link in links:
            q_link, t_link = link.sample(t)
            if q is None:
                q, tr = q_link, t_link
            else:  # T_parent_bottom = T_parent_child T_child_bottom
                q, tr = quat_multiply(q_link, q), t_link + quat_rotate(q_link, tr)
        return q, tr


def _latest_common_time(up: list[_Link], down: list[_Link]) -> float | None:
    newest = [link.stamps[-1] for link in (*up, *down) if not link.static]
    return float(min(newest)) if newest else None


def _matrix_arg(T) -> np.ndarray:
    m = np.asarray(T, dtype=np.float64)
    if m.shape[-2:] != (4, 4) or m.ndim not in (2, 3):
        raise ShapeError(f"T must have shape (4, 4) or (N, 4, 4), got {m.shape}")
    return m


def _check_range(link: _Link, t: np.ndarray, target: str, source: str) -> None:
    stamps = link.stamps
    first, last = float(stamps[0]), float(stamps[-1])
    lo, hi = float(t.min()), float(t.max())
    held = (
        f"it holds one sample, at t={first!r}, and can be looked up only at that time"
        if stamps.shape[0] == 1
        else f"it holds {stamps.shape[0]} samples over [{first!r}, {last!r}] s"
    )
    where = f"looking up {target!r} <- {source!r}: link {link.parent!r} -> {link.child!r}"
    if lo < first:
        raise ExtrapolationError(
            f"{where}: requested time t={lo!r} is before the first sample at t={first!r} "
            f"(extrapolation into the past; {held})"
        )
    if hi > last:
        raise ExtrapolationError(
            f"{where}: requested time t={hi!r} is after the last sample at t={last!r} "
            f"(extrapolation into the future; {held})"
        )


def _describe(link: _Link) -> str:
    if link.static:
        return "[static]"
    n = len(link)
    stamps = link.stamps
    if n == 1:
        return f"[1 sample, t={float(stamps[0])!r}]"
    return f"[{n} samples, t={float(stamps[0])!r}..{float(stamps[-1])!r}]"
