"""Where the shared real-robot data lives (never inside the repository)."""

from __future__ import annotations

import os
from pathlib import Path


def find_shared_data(start: Path | None = None) -> Path | None:
    """``$OCCMAP_DATA`` if set, else ``../shared/data`` beside the project checkout that contains
    ``start`` (default: the working directory); None when neither holds the data's README."""
    env = os.environ.get("OCCMAP_DATA")
    candidates = [Path(env)] if env else []
    here = (start or Path.cwd()).resolve()
    candidates += [p.parent / "shared" / "data" for p in (here, *here.parents)]
    for c in candidates:
        if (c / "README.md").is_file():
            return c
    return None
