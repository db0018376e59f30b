"""Canonical sensor names used by preprocessing (see tonguevis.io.sensor_map)."""

from __future__ import annotations

TONGUE = ("TT", "TB", "TD", "TBK", "TL", "TR")
JAW = "JAW"


def is_reference(name: str) -> bool:
    """Head reference sensors are named REF1, REF2, ... (also plain REF)."""
    return name.upper().startswith("REF")


def reference_names(names) -> list[str]:
    return [n for n in names if is_reference(n)]


def tongue_names(names) -> list[str]:
    return [n for n in names if n in TONGUE]
