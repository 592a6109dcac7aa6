"""Response bodies of the REST API (also the typed results of :mod:`service.client`).

Plain pydantic models, no FastAPI import: the client uses them too.
"""
from __future__ import annotations

import datetime as dt
from typing import Any, Literal

from pydantic import BaseModel, Field

JobState = Literal["accepted", "running", "successful", "failed", "dismissed"]
Reason = Literal["solver_diverged", "nonfinite_state", "timeout", "cancelled_by_user", "internal_error"]


class JobError(BaseModel):
    reason: Reason | None = Field(None, description="Machine-readable reason of the terminal state.")
    message: str | None = Field(None, description="The solver's (or the service's) message.")
    time: float | None = Field(None, description="Simulated time where the solve stopped, s.")
    step: int | None = Field(None, description="Time step where the solve stopped.")


class JobLinks(BaseModel):
    self: str
    spec: str
    results: str
    variables: str
    summary: str


class JobStatus(BaseModel):
    id: str = Field(..., description="Job id (UUID).")
    kind: Literal["dynamic", "continuation"] = Field(
        "dynamic", description="dynamic: a run of the case (POST /v1/jobs); continuation: a "
        "static branch (POST /v1/continuations), whose result is the branch dataset "
        "(dimension point) and whose step counts the points done.")
    name: str | None = Field(None, description="The case's name.")
    state: JobState
    reason: Reason | None = Field(None, description="Set on failed and dismissed jobs.")
    message: str | None = None
    progress: float = Field(..., ge=0, le=100, description="Simulated time over t_end, percent "
                            "(a continuation: the larger of points done over max_points and "
                            "the parameter's way to its target).")
    sim_time: float = Field(..., description="Simulated time reached, s.")
    t_end: float = Field(..., description="End time of the run, s.")
    step: int = Field(..., description="Time steps done.")
    n_steps: int = Field(..., description="Time steps at the nominal dt.")
    grid_points: int
    eta_seconds: float | None = Field(None, description="Estimated wall-clock seconds left.")
    wall_time: float | None = Field(None, description="Wall-clock seconds the solve has run.")
    created: dt.datetime
    started: dt.datetime | None = None
    finished: dt.datetime | None = None
    updated: dt.datetime
    worker: str | None = Field(None, description="Worker node that runs or ran it.")
    attempts: int = Field(..., description="Deliveries that started a solve (2+: a worker died).")
    cancel_requested: bool
    spec_hash: str
    solver_version: str
    time_limit: float = Field(..., description="Hard time limit of the job, s.")
    result_available: bool = Field(..., description="A NetCDF result (maybe partial) can be fetched.")
    result_partial: bool = Field(..., description="The result stops before t_end.")
    error: JobError | None = Field(None, description="Set on failed and dismissed jobs.")
    reused: Literal["identical_case", "idempotency_key"] | None = Field(
        None, description="Set only on the answer to a submission that created no job: "
        "identical_case, the result of an earlier successful job with the same case and "
        "solver version is reused (submit with ?fresh=true to run it again); "
        "idempotency_key, a retry of an earlier request with the same Idempotency-Key. Also "
        "in the Hockle-Reused header.")
    advice: list[str] = Field(
        default_factory=list, description="Set only on the answer to a submission: advice "
        "on the case as given, each naming the fields to change (a start pose more than a "
        "tenth of the diameter off its initial.centreline; docs/case-spec.md). The case "
        "runs as given; its result carries the advice as the attribute hockle_advice.")
    warnings: list[dict[str, str]] = Field(
        default_factory=list, description="Set only on the answer to a submission: the "
        "case's inputs that look wrong by a unit or lie outside what the model is for, each "
        "{loc, msg, type} as a 422's errors (a Young's modulus of 12.5 Pa meant as MPa, "
        "lengths in mm, a step above the rod's slowest bending period; "
        "solver.plausibility). The case runs as given; its result carries them as the "
        "attribute hockle_input_warnings.")
    links: JobLinks

    @property
    def terminal(self) -> bool:
        return self.state in ("successful", "failed", "dismissed")


class JobList(BaseModel):
    jobs: list[JobStatus]
    next_page_token: str | None = Field(None, description="Pass as page_token for the next page.")
    next: str | None = Field(None, description="URL of the next page.")


class VariableInfo(BaseModel):
    name: str
    dims: list[str]
    shape: list[int]
    dtype: str
    units: str | None = None
    long_name: str | None = None
    coordinate: bool = Field(False, description="A coordinate (time, s, component, ...).")


class VariableList(BaseModel):
    job_id: str
    dims: dict[str, int]
    variables: list[VariableInfo]


class VariableSlice(BaseModel):
    job_id: str
    name: str
    dims: list[str]
    shape: list[int]
    units: str | None = None
    long_name: str | None = None
    coords: dict[str, list[Any]] = Field(..., description="Coordinate values along each kept dim.")
    selected: dict[str, Any] = Field(
        default_factory=dict, description="Dims reduced to one value by the query, and where."
    )
    data: Any = Field(..., description="Nested lists in the order of dims; null for NaN.")


class Series(BaseModel):
    units: str | None = None
    long_name: str | None = None
    values: list[float | None]


class Summary(BaseModel):
    job_id: str
    state: JobState
    partial: bool
    time: list[float]
    series: dict[str, Series]


class Check(BaseModel):
    ok: bool
    detail: str | None = None


class Health(BaseModel):
    status: Literal["ok", "degraded", "unavailable"]
    mode: Literal["embedded", "distributed"]
    solver_version: str
    registry: Check
    broker: Check
    result_store: Check
    workers: list[dict[str, Any]] = Field(
        default_factory=list, description="Workers seen lately: name, last seen, current job. "
        "With API keys configured, only for a request with a valid key (the check itself "
        "needs none); workers_seen counts them for everyone.")
    workers_seen: int = Field(0, description="How many workers were seen lately.")
    jobs: dict[str, int] = Field(default_factory=dict, description="Jobs per state.")
