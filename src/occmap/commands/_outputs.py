"""Output names checked before a command reads anything: no file written twice, no input
overwritten (the other half of a map_server pair counts as an output of its own)."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import InvalidArgumentError


def _same(a: Path, b: Path) -> bool:
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)  # hard links
    except OSError:
        return False


def check_outputs(outputs: dict[str, object], inputs: dict[str, object] | None = None) -> None:
    """Refuse the command when two ``outputs`` name one file or an output names one of ``inputs``.

    Both map a description (``"-o"``, ``"the map's image"``, ``"LOG"``) to a path; ``None``
    values (options not given) are skipped. Raises :class:`InvalidArgumentError` naming both.
    """
    outs = [(what, Path(p)) for what, p in outputs.items() if p is not None]
    ins = [(what, Path(p)) for what, p in (inputs or {}).items() if p is not None]
    for i, (what, path) in enumerate(outs):
        for other, other_path in outs[:i]:
            if _same(path, other_path):
                raise InvalidArgumentError(f"{what} {str(path)!r} and {other} {str(other_path)!r} are one file: "
                                           "the second would overwrite the first")
        for other, other_path in ins:
            if _same(path, other_path):
                raise InvalidArgumentError(f"{what} {str(path)!r} would overwrite {other} {str(other_path)!r}")


def check_suffix(what: str, path, suffixes: tuple[str, ...]) -> None:
    """Refuse an output whose extension is not one of ``suffixes`` (lower case, with the dot)."""
    if Path(path).suffix.lower() not in suffixes:
        raise InvalidArgumentError(f"{what} {str(path)!r} must end in {' or '.join(suffixes)}")
