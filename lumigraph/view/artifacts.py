"""The artifact kinds ``lumigraph view`` can show, each read by the project's own reader.

Filled in by the looking mode (issue 18, part B).
"""

from __future__ import annotations

from pathlib import Path

KINDS: dict[str, tuple[str, ...]] = {}


def kind_of(path) -> str | None:
    """The artifact kind of ``path`` (None: not one the page shows).

    >>> kind_of("notes.txt") is None
    True
    """
    p = Path(path)
    for kind, suffixes in KINDS.items():
        if p.name.lower().endswith(suffixes):
            return kind
    return None
