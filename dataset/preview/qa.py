"""A sample's QA figures as rows for people: named, formatted, and marked when a flag concerns them.

Generation writes flags as sentences ("holes 25% > 20%", "SGBM EPE 3.10 px > 2", "pair 1 …"); a
row is flagged when a flag starts with the row's prefix. Pairs are numbered for people, from 1 in the
order of their stored ids, as the Annotate page numbers its planes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Row:
    label: str
    value: str
    flagged: bool = False
    hint: str = ""


@dataclass(frozen=True)
class PairRow:
    pair: int  # its number for people, from 1 (not its stored id)
    status: str
    reason: str
    illusion_px: str
    support: str
    overlap: str
    inlier_ratio: str
    residual: str
    plane: str
    flagged: bool


def _number(value: Any, unit: str = "", digits: int = 3) -> str:
    if value is None:
        return "–"
    return f"{float(value):.{digits}g}{unit}"


def _percent(value: Any) -> str:
    return "–" if value is None else f"{100 * float(value):.1f} %"


def _flagged(flags: list[str], prefix: str) -> bool:
    return any(flag.startswith(prefix) for flag in flags)


def summary_rows(qa: dict[str, Any]) -> list[Row]:
    """The sample-wide figures: scale, holes, SGBM self-consistency, CPU time."""
    flags = qa.get("flags", [])
    return [
        Row("Disparity scale", _number(qa.get("scale"), " px/unit"),
            hint="px of the right view per unit of the monocular disparity"),
        Row("Holes in the right view", _percent(qa.get("hole_fraction")), _flagged(flags, "holes"),
            "share of right-view pixels no source landed on (inpainted)"),
        Row("SGBM end-point error", _number(qa.get("stereo_epe"), " px"), _flagged(flags, "SGBM EPE"),
            "SGBM on the synthesized pair against the stored disparity"),
        Row("SGBM bad-2", _percent(qa.get("stereo_bad2")), hint="pixels off by more than 2 px"),
        Row("SGBM coverage", _percent(qa.get("stereo_coverage")), hint="pixels SGBM matched"),
        Row("CPU time", _number(qa.get("cpu_s"), " s")),
    ]


def pair_rows(qa: dict[str, Any]) -> list[PairRow]:
    """One row per illusion/support pair, flagged when a flag names its pair."""
    flags = qa.get("flags", [])
    return [PairRow(
        pair=number,
        status=pair.get("status") or "–",
        reason=pair.get("reason") or "",
        illusion_px=str(pair.get("illusion_px", "–")),
        support=f"{pair.get('support_px', '–')} px ({pair.get('support_source') or '–'})",
        overlap=_percent(pair.get("overlap")),
        inlier_ratio=_percent(pair.get("inlier_ratio")),  # the share of the fitted points: read as %
        residual=_number(pair.get("residual")),
        plane=", ".join(_number(c) for c in pair.get("plane") or []) or "–",
        flagged=_flagged(flags, f"pair {number} "),
    ) for number, pair in enumerate(qa.get("pairs", []), 1)]
