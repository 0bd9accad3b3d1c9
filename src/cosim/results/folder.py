"""Where a study writes its results folder by default (no pandas or pyarrow: the command line needs it first)."""

from __future__ import annotations

import json
import re
from pathlib import Path


def default_folder(spec_path: str | Path) -> Path:
    """Where ``cosim sweep`` writes without ``--out``: ``results/<spec name>`` (the file's stem without a name)."""
    try:
        name = json.loads(Path(spec_path).read_text(encoding="utf-8")).get("name") or Path(spec_path).stem
    except (OSError, ValueError, AttributeError, RecursionError):  # a broken spec: validation reports it next
        name = Path(spec_path).stem
    return Path("results") / re.sub(r"[^A-Za-z0-9_.-]+", "_", str(name))
