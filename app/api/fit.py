"""Debugging a tab's ellipsoid fit: the Fit panel's rows, one ellipsoid at a time, a kind's fit at another T.

Per viewer (a tab), like its layers: ``GET /api/scene/{viewer}/fit``, ``PUT /api/scene/{viewer}/fit`` (a kind
refitted at T in the session's worker, or back to the plan's fit; the plan never changes) and
``PUT /api/scene/{viewer}/fit/focus`` (highlight one ellipsoid and its voxels). app/scene/fit_view.py does it.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter
from pydantic import BaseModel, ConfigDict, Field, StrictInt

from app.api.deps import Scene

router = APIRouter(prefix="/scene/{viewer}/fit", tags=["scene"])


class FitKindOut(BaseModel):
    kind: Literal["occupied", "frontier"]
    t_plan: int = Field(description="the plan's T (chosen by BIC)")
    t_shown: int = Field(description="the T this viewer shows (a refit's, else the plan's ellipsoid count)")
    refit: bool = Field(description="this viewer shows a fit at another T, not the plan's")
    ellipsoids: int
    voxels: int
    bic: float | None = Field(description="the refit's BIC (null for the plan's fit: see the BIC chart)")
    low_fill: int = Field(description="ellipsoids flagged for a fill ratio below low_fill_threshold")


class FitRowOut(BaseModel):
    kind: Literal["occupied", "frontier"]
    label: str = Field(description="O3 / F0: as the inspector names it")
    index: int = Field(description="index among this kind's ellipsoids")
    voxels: int
    volume: float = Field(description="the ellipsoid's volume, m^3")
    voxel_volume: float = Field(description="its cluster's voxels' volume, m^3")
    fill: float = Field(description="fill ratio: voxel_volume / volume")
    weight: float | None = Field(description="the GMM component's weight")
    weighted: float | None = Field(description="its w·L in the selected candidate's score (null: none, or a refit)")
    low_fill: bool = Field(description="fill < low_fill_threshold: covers far more space than its voxels")
    color: list[int] = Field(description="RGB of its cluster in the clusters layer")


class FitOut(BaseModel):
    viewer: str
    session: str
    plan_id: str
    selected: int | None
    focus: str | None = Field(description="the ellipsoid highlighted in this viewer (its label)")
    low_fill_threshold: float
    kinds: list[FitKindOut]
    rows: list[FitRowOut] = Field(description="per kind (occupied, then frontier), worst-filled first")


class RefitRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    kind: Literal["occupied", "frontier"]
    t: Annotated[StrictInt, Field(ge=1)] | None = Field(description="components; null: back to the plan's fit")


class FocusRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    label: Annotated[str, Field(max_length=16)] | None = Field(description="O3 / F0; null: no focus")


@router.get("", response_model=FitOut)
def fit(scene: Scene, viewer: str) -> dict[str, Any]:
    """The Fit panel of this viewer: the T shown per kind and one row per ellipsoid, worst-filled first."""
    return scene.fit.info(viewer)


@router.put("", response_model=FitOut)
def refit(scene: Scene, viewer: str, body: RefitRequest) -> dict[str, Any]:
    """Show ``kind`` fitted at ``t`` components in this viewer (fitted now in the session's worker; the plan
    stays as it is), or the plan's fit again with ``t: null``. Turns the clusters layer on."""
    return scene.fit.refit(viewer, body.kind, body.t)


@router.put("/focus", response_model=FitOut)
def focus(scene: Scene, viewer: str, body: FocusRequest) -> dict[str, Any]:
    """Highlight one ellipsoid and its voxels in this viewer's clusters layer (the rest dimmed); null: none."""
    return scene.fit.focus(viewer, body.label)


routers = [router]
