"""Whether a bag's connection defines its message type as ROS does: occmap's decoders read the
standard layout from the bytes (:mod:`.wire`), so a custom or old definition under a standard
name (a field added, renamed, retyped) would be read wrongly without a word.

A definition is standard when its *layout* — every field's name and type, in order, nested types
expanded — is the one ``rosbags`` ships for the type: ROS 1's (the Noetic store, with tf2's
``TFMessage``, which it lacks, taken from the ROS 2 store: its one field is a list of Noetic's
``TransformStamped``) for ``"ros1"`` bags, the latest ROS 2 distribution's for ``"cdr"`` ones.
Constants and the names of nested types do not count (they change no byte). The digest a
connection carries settles the common case without parsing: ROS 1's md5sum, and ROS 2's
``RIHS01`` type hash, equal to the standard type's. Otherwise the definition text (ROS 1
connection headers, MCAP schemas, ROS 2 metadata; ``.msg`` or ``.idl``) is parsed and the
layouts compared. A ROS 2 bag that records no definition (sqlite3 bags before Iron) is read as
standard: it names nothing else.
"""

from __future__ import annotations

from functools import cache, lru_cache

from ...errors import FormatError

__all__ = ["TF_TYPES", "check_definition", "difference", "standard_digest", "standard_store"]

TFMESSAGE, TF1MESSAGE = "tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"
#: tf2's message, and ROS 1's older tf/tfMessage with the same fields
TF_TYPES = (TFMESSAGE, TF1MESSAGE)

#: tf2_msgs/msg/TFMessage.msg, the same file in ROS 1 and ROS 2 (Noetic's store lacks tf2_msgs)
_TFMESSAGE_MSG = "geometry_msgs/TransformStamped[] transforms"


@cache
def standard_store(encoding: str):
    """``rosbags``' type store of the standard definitions for bags of ``encoding``, with ROS 1's
    tf messages (loading a store costs 0.1-0.3 s, once per process)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.LATEST if encoding == "cdr" else Stores.ROS1_NOETIC)
    if TFMESSAGE not in store.fielddefs:
        store.register(get_types_from_msg(_TFMESSAGE_MSG, TFMESSAGE))
    store.register({TF1MESSAGE: store.fielddefs[TFMESSAGE]})
    return store


@cache
def standard_digest(encoding: str, msgtype: str) -> str:
    """The digest a standard ``msgtype`` carries: ROS 1's md5sum (``"ros1"``), ROS 2's RIHS01
    type hash (``"cdr"``)."""
    store = standard_store(encoding)
    return store.generate_msgdef(msgtype, ros_version=1)[1] if encoding == "ros1" else store.hash_rihs01(msgtype)


def _layout(fielddefs: dict, msgtype: str, prefix: str = "") -> list[tuple[str, str]]:
    """``(field path, type)`` of every field of ``msgtype`` in order, nested types expanded
    (``header.stamp.sec``; a list of messages as ``transforms[].header...``)."""
    from rosbags.typesys.base import Nodetype

    def base(desc) -> str:
        name, bound = desc
        return f"{name}<={bound}" if bound else name

    out = []
    for name, (node, desc) in fielddefs[msgtype][1]:
        path = prefix + name
        if node == Nodetype.BASE:
            out.append((path, base(desc)))
        elif node == Nodetype.NAME:
            out += _layout(fielddefs, desc, path + ".")
        else:
            (inner, what), count = desc
            brackets = f"[{count}]" if node == Nodetype.ARRAY else f"[<={count}]" if count else "[]"
            if inner == Nodetype.BASE:
                out.append((path, base(what) + brackets))
            else:
                out.append((path, brackets))
                out += _layout(fielddefs, what, path + "[].")
    return out


def _differences(declared: list[tuple[str, str]], standard: list[tuple[str, str]], limit: int = 4) -> str:
    """What ``declared`` (a layout, see :func:`_layout`) does differently from ``standard``, in
    words; empty when they are the same."""
    if declared == standard:
        return ""
    have, want = dict(declared), dict(standard)
    said = [f"field {p} is {have[p]}, not {t}" for p, t in standard if p in have and have[p] != t]
    said += [f"lacks field {p} ({t})" for p, t in standard if p not in have]
    said += [f"has an extra field {p} ({t})" for p, t in declared if p not in want]
    if not said:
        said = ["the same fields in another order"]
    return "; ".join(said[:limit]) + (f"; and {len(said) - limit} more" if len(said) > limit else "")


@lru_cache(maxsize=64)
def difference(encoding: str, msgtype: str, digest: str, form: str, text: str) -> str:
    """How a connection's definition of ``msgtype`` (``digest``; ``text`` in ``form`` ``"msg"``,
    ``"idl"`` or ``""`` for none) differs from the standard layout for ``encoding``, in words;
    empty when it is standard (see the module's docstring) or the type is not one ``rosbags``
    ships."""
    store = standard_store(encoding)
    if msgtype not in store.fielddefs or digest == standard_digest(encoding, msgtype):
        return ""
    if not text.strip():
        if encoding == "cdr":
            return ""
        return f"md5sum {digest!r}, not the standard {standard_digest(encoding, msgtype)!r}"
    from rosbags.typesys import get_types_from_idl, get_types_from_msg

    try:
        declared = get_types_from_idl(text) if form == "idl" else get_types_from_msg(text, msgtype)
    except Exception as e:  # rosbags' parser raises its own errors and others on text it cannot read
        return f"its definition does not parse ({type(e).__name__}: {e})"
    fielddefs = {**store.fielddefs, **{k: v[:2] for k, v in declared.items()}}
    if "roslib/msg/Header" in declared and "std_msgs/msg/Header" not in declared:
        # before ROS C Turtle (2010) "Header" meant roslib/Header; rosbags reads it as std_msgs'
        fielddefs["std_msgs/msg/Header"] = declared["roslib/msg/Header"][:2]
    try:
        layout = _layout(fielddefs, msgtype)
    except KeyError as e:
        return f"its definition uses type {e.args[0]}, which it does not define"
    return _differences(layout, _layout(store.fielddefs, msgtype))


def check_definition(path, topic: str, msgtype: str, encoding: str, digest: str, form: str, text: str) -> None:
    """Raise :class:`FormatError` naming the bag at ``path``, ``topic``, ``msgtype`` and what
    differs when a connection's definition (``digest``, ``text`` in ``form`` ``"msg"``,
    ``"idl"`` or ``""``) is not the standard layout of ``msgtype`` for ``encoding``."""
    said = difference(encoding, msgtype, digest or "", form, text or "")
    if said:
        raise FormatError(path, f"topic {topic!r} declares its own {msgtype}, not the standard one occmap decodes: "
                          f"{said}")
