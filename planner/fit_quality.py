"""How well each ellipsoid of a fit encloses its cluster: names, volumes, fill ratios, the worst first.

For debugging fits by eye (the workbench's Fit panel). An ellipsoid is named like the inspector names it:
the kind's initial and its index among the ellipsoids of that kind, in ``PlanResult.ellipsoids`` order
(``O0, O1, ..., F0, F1, ...``).

Fill ratio = the volume of the cluster's voxels / the ellipsoid's volume, ``n res^3 / (4/3 pi a b c)``, in
(0, ~1]: 1 would be an ellipsoid full of its voxels (never quite: the MVEE encloses the voxel cubes, whose
union is not an ellipsoid). A low fill ratio is an ellipsoid that covers far more space than its voxels: a
frontier ellipsoid then overstates the frontier a view would see, an occupied one the surface that hides it.
Below :data:`LOW_FILL` the ellipsoid is flagged (docs/method.md, "Fit diagnostics").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from planner.types import Ellipsoid, EllipsoidKind

LOW_FILL = 0.05
"""An ellipsoid whose voxels fill less than this fraction of it (it covers over 20x their volume) is flagged."""


def ellipsoid_label(kind: EllipsoidKind, index: int) -> str:
    """``O3`` / ``F0``: the kind's initial and the index among that kind's ellipsoids."""
    return f"{kind[0].upper()}{index}"


def ellipsoid_volume(e: Ellipsoid) -> float:
    """4/3 pi a b c, cubic metres."""
    return 4.0 / 3.0 * math.pi * float(e.axes[0] * e.axes[1] * e.axes[2])


def fill_ratio(e: Ellipsoid, resolution: float) -> float:
    """``e.n_points`` voxels of edge ``resolution`` (metres) over the ellipsoid's volume."""
    if not math.isfinite(resolution) or resolution <= 0:
        raise ValueError(f"resolution: must be a finite number > 0, got {resolution!r}")
    return e.n_points * resolution**3 / ellipsoid_volume(e)


@dataclass(frozen=True)
class FitRow:
    """One ellipsoid of a fit. index: among its kind's ellipsoids; plan_index: in the ellipsoid tuple given;
    volume: m^3; voxel_volume: its cluster's voxels, m^3; weight: its GMM component's weight (None: unknown);
    low_fill: fill < LOW_FILL."""

    kind: EllipsoidKind
    label: str
    index: int
    plan_index: int
    voxels: int
    volume: float
    voxel_volume: float
    fill: float
    weight: float | None
    low_fill: bool


def fit_rows(ellipsoids: Sequence[Ellipsoid], resolution: float) -> list[FitRow]:
    """One row per ellipsoid, in the given order (labels counted per kind)."""
    counts: dict[str, int] = {"occupied": 0, "frontier": 0}
    rows = []
    for j, e in enumerate(ellipsoids):
        i = counts[e.kind]
        counts[e.kind] += 1
        fill = fill_ratio(e, resolution)
        rows.append(
            FitRow(
                kind=e.kind,
                label=ellipsoid_label(e.kind, i),
                index=i,
                plan_index=j,
                voxels=int(e.n_points),
                volume=ellipsoid_volume(e),
                voxel_volume=e.n_points * resolution**3,
                fill=fill,
                weight=e.gmm_weight,
                low_fill=fill < LOW_FILL,
            )
        )
    return rows


def worst_filled_first(rows: Sequence[FitRow]) -> list[FitRow]:
    """Occupied rows then frontier rows, each by fill ratio ascending (ties: label order)."""
    kind_order = {"occupied": 0, "frontier": 1}
    return sorted(rows, key=lambda r: (kind_order[r.kind], r.fill, r.index))
