"""Lists of names in a one-line message: the first few, then how many more."""

from __future__ import annotations

from collections.abc import Sequence


def first_names(items: Sequence[str], shown: int = 5) -> str:
    """``"a, b, c and 4 more"``: the first ``shown`` of ``items``, then how many are left
    out, so that a message naming many joints, markers or takes stays one line."""
    more = f" and {len(items) - shown} more" if len(items) > shown else ""
    return ", ".join(items[:shown]) + more


def bare_name(name: str) -> str:
    """A joint's or marker's name without a namespace or subject prefix (the text up to the
    last ``:``: Mixamo's ``mixamorig:Hips``, Vicon's ``Subject:Marker``)."""
    return name.rsplit(":", 1)[-1]
