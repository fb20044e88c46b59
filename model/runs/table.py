"""The paper's Table 1 layout (Method, checkpoint | EPE, bad2, bad3, bad5 | AbsRel, RMSE, δ1, per
region) for every method a workspace has: which evaluations to run (:func:`plan_rounds`), and the table
from their reports (:func:`table_rows`, :func:`format_table`). Pure: the command line runs the jobs.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from model.methods import BASELINE_METHODS, FUSION_METHODS

# The columns of the paper's Table 1: disparity space (EPE px, bad-x %), then depth space (AbsRel,
# RMSE m, δ1 %) where a camera turns disparity into depth.
COLUMNS: tuple[tuple[str, str], ...] = (("epe", "EPE"), ("bad2", "bad2"), ("bad3", "bad3"), ("bad5", "bad5"),
                                        ("abs_rel", "AbsRel"), ("rmse", "RMSE"), ("delta1", "δ1"))
# Rows in the paper's order: monocular, then stereo networks, then ours; SGBM (no network) last.
ROW_ORDER = ("mono_gt_align", *BASELINE_METHODS, "stereo", "mono_align", "fusion", "sgbm")
TITLES = {"mono_gt_align": "mono + GT align", "stereo": "ours: stereo branch", "mono_align": "ours: mono aligned",
          "fusion": "ours", "sgbm": "SGBM",
          **{key: baseline.title for key, baseline in BASELINE_METHODS.items()}}
CURRENT = ""  # a round's checkpoint for the fusion methods: the workspace's current model


@dataclass(frozen=True)
class Round:
    """One evaluation: its methods (report keys) and each network method's checkpoint name (``CURRENT``:
    the current model)."""

    methods: tuple[str, ...]
    checkpoints: Mapping[str, str]


def plan_rounds(has_current: bool, imported: Iterable[tuple[str, str]]) -> list[Round]:
    """The evaluations that score every method once per checkpoint: ``imported`` = (``imported:NAME``,
    baseline method key) pairs. One evaluation takes one checkpoint per method, so a second import of
    the same network goes to a second round; the first round also has SGBM, the GT-aligned mono and,
    with a current model, its fused, stereo and mono outputs."""
    by_method: dict[str, list[str]] = {}
    for name, method in imported:
        by_method.setdefault(method, []).append(name)
    rounds = []
    for index in range(max((len(names) for names in by_method.values()), default=0) or 1):
        checkpoints = {m: names[index] for m, names in by_method.items() if index < len(names)}
        methods = list(checkpoints)
        if index == 0:
            methods += ["mono_gt_align", "sgbm", *(FUSION_METHODS if has_current else ())]
            checkpoints.update({m: CURRENT for m in FUSION_METHODS if has_current})
        rounds.append(Round(tuple(sorted(methods, key=ROW_ORDER.index)), checkpoints))
    return rounds


@dataclass(frozen=True)
class Row:
    """One line of the table: the method's title, the checkpoint it ran, its figures per region (mean
    over samples; NaN where not measured), and why it has none (every sample failed)."""

    method: str
    title: str
    checkpoint: str
    regions: Mapping[str, Mapping[str, float]]
    samples: int
    missing: str = ""


def table_rows(evaluations: Sequence[tuple[Round, Mapping[str, Any], str]]) -> list[Row]:
    """The rows of ``evaluations`` = (round, its report.json, the current model's name), in ROW_ORDER."""
    rows = []
    for plan, report, current in evaluations:
        for method, result in report["methods"].items():
            checkpoint = plan.checkpoints.get(method)
            failures = [f["reason"] for f in report.get("failed", []) if f.get("method") == method]
            rows.append(Row(method, TITLES.get(method, method), current if checkpoint == CURRENT else checkpoint or "",
                            result.get("regions", {}), len(result.get("per_sample", [])),
                            failures[0] if failures and not result.get("per_sample") else ""))
    return sorted(rows, key=lambda row: ROW_ORDER.index(row.method) if row.method in ROW_ORDER else len(ROW_ORDER))


def table_regions(rows: Sequence[Row], wanted: Sequence[str] = ()) -> list[str]:
    """The regions to print: ``wanted`` (in its order) or every region a row has, ``all`` first, then
    ``illusion`` and the rest as the reports list them."""
    if wanted:
        return list(wanted)
    seen: list[str] = []
    for row in rows:
        seen += [region for region in row.regions if region not in seen]
    return sorted(seen, key=lambda r: (r != "all", r != "illusion", seen.index(r)))


def format_table(rows: Sequence[Row], regions: Sequence[str], *, markdown: bool = False) -> str:
    """One block per region in the paper's layout: fixed-width text, or Markdown tables. Depth columns
    are dropped where no row has them (no camera); a row without figures says why."""
    blocks = []
    for region in regions:
        columns = [(key, label) for key, label in COLUMNS
                   if any(_finite(row.regions.get(region, {}).get(key)) for row in rows)] or list(COLUMNS[:4])
        header = ["Method", "Checkpoint", *(label for _, label in columns)]
        lines = [[row.title, row.checkpoint or "–",
                  *((_number(row.regions.get(region, {}).get(key)) for key, _ in columns)
                    if region in row.regions else [f"– ({row.missing or 'not in these samples'})"])]
                 for row in rows]
        blocks.append(_markdown(region, header, lines) if markdown else _text(region, header, lines))
    return "\n\n".join(blocks)


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and math.isfinite(value)


def _number(value: Any) -> str:
    """3 decimals below 10, 2 above; ``inf`` where a mean met an infinite depth (a zero disparity), ``–`` unmeasured."""
    if isinstance(value, (int, float)) and math.isinf(value):
        return "inf"
    return f"{value:.3f}" if _finite(value) and abs(value) < 10 else f"{value:.2f}" if _finite(value) else "–"


def _text(region: str, header: list[str], lines: list[list[str]]) -> str:
    full = [line for line in lines if len(line) == len(header)]  # (a row without figures: title, checkpoint, why)
    widths = [max(len(line[i]) for line in [header, *(lines if i < 2 else full)]) for i in range(len(header))]
    rule = "-" * (sum(widths) + 2 * (len(widths) - 1))
    return "\n".join([f"region: {region}", _text_line(header, widths), rule, *(_text_line(line, widths) for line in lines)])


def _text_line(line: list[str], widths: list[int]) -> str:
    """Method and checkpoint left-aligned, figures right-aligned; a row without figures gives its reason."""
    head = [cell.ljust(widths[i]) for i, cell in enumerate(line[:2])]
    if len(line) != len(widths):
        return "  ".join([*head, *line[2:]]).rstrip()
    return "  ".join([*head, *(cell.rjust(widths[i + 2]) for i, cell in enumerate(line[2:]))])


def _markdown(region: str, header: list[str], lines: list[list[str]]) -> str:
    rows = [header, ["---"] * len(header), *(line + [""] * (len(header) - len(line)) for line in lines)]
    return "\n".join([f"**{region}**", "", *("| " + " | ".join(row) + " |" for row in rows)])
