"""Typed Python client of the hockle service (httpx)::

    from service.client import HockleClient
    with HockleClient("http://127.0.0.1:8000", api_key="...") as client:   # or HOCKLE_API_KEY
        job = client.submit("cases/goyal-writhing.yaml")
        job = client.wait(job.id, on_progress=lambda j: print(j.state, j.progress))
        ds = client.dataset(job.id)              # xarray.Dataset
        kappa3 = client.variable(job.id, "kappa", time="0:1", component=3)

Every non-2xx answer raises :class:`HockleAPIError` carrying the problem details.
"""
from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

import httpx

from .schemas import Health, JobList, JobStatus, Summary, VariableList, VariableSlice

__all__ = ["HockleClient", "HockleAPIError", "case_payload", "case_document"]

TERMINAL = ("successful", "failed", "dismissed")


class HockleAPIError(RuntimeError):
    """An error answer of the service.

    Parameters
    ----------
    status : int
        The HTTP status.
    problem : dict
        The answer's problem details (RFC 9457, ``application/problem+json``).

    Attributes
    ----------
    status : int
        The HTTP status.
    problem : dict
        The problem details: ``type``, ``title``, ``detail`` and, for an invalid case,
        ``errors``.
    """

    def __init__(self, status: int, problem: dict[str, Any]):
        self.status = status
        self.problem = problem
        detail = problem.get("detail") or problem.get("title") or f"HTTP {status}"
        lines = [f"{status}: {detail}"]
        for err in problem.get("errors") or []:
            lines.append(f"  {err.get('loc') or '(document)'}: {err.get('msg')}")
        super().__init__("\n".join(lines))

    @property
    def errors(self) -> list[dict[str, Any]]:
        """The problem's field errors: ``{"loc", "msg", "type"}`` each (empty if none)."""
        return list(self.problem.get("errors") or [])


def case_payload(case: str | os.PathLike | Mapping[str, Any] | Any) -> tuple[bytes, str]:
    """The request body and content type for a case.

    Files are sent as they are (YAML as ``application/yaml``): the server parses them with the
    same reader as ``hockle run``.

    Parameters
    ----------
    case : str or os.PathLike or mapping or solver.Case
        A case file (.yaml, .yml, .json), a mapping or a validated case.

    Returns
    -------
    tuple of (bytes, str)
        The body and its content type.

    Raises
    ------
    ValueError
        A file name that is not a case file's.
    """
    if isinstance(case, Mapping):
        return json.dumps(dict(case)).encode(), "application/json"
    if hasattr(case, "canonical_json"):
        return case.canonical_json().encode(), "application/json"
    path = Path(case)
    suffix = path.suffix.lower()
    if suffix not in (".yaml", ".yml", ".json"):
        raise ValueError(f"{path}: a case file ends in .yaml, .yml or .json")
    return path.read_bytes(), "application/json" if suffix == ".json" else "application/yaml"


def case_document(case: str | os.PathLike | Mapping[str, Any] | Any) -> dict[str, Any]:
    """A case as a JSON-able mapping (the base of a sweep or a continuation).

    Parameters
    ----------
    case : str or os.PathLike or mapping or solver.Case
        A mapping (returned as it is), a validated case (dumped) or a case file (.yaml,
        .yml, .json; parsed with the case reader, not yet validated).

    Returns
    -------
    dict

    Raises
    ------
    ValueError
        A file name that is not a case file's, or a file that is not a mapping.
    """
    if isinstance(case, Mapping):
        return dict(case)
    if hasattr(case, "model_dump"):
        return case.model_dump(mode="json")
    from solver.case import parse_text

    path = Path(case)
    if path.suffix.lower() not in (".yaml", ".yml", ".json"):
        raise ValueError(f"{path}: a case file ends in .yaml, .yml or .json")
    doc = parse_text(path.read_bytes(), path.suffix, str(path))
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: a case spec is a mapping of fields")
    return doc

class HockleClient:
    """A client of one hockle service; a context manager that closes its connections.

    Every non-2xx answer raises :class:`HockleAPIError` with the problem details.

    Parameters
    ----------
    base_url : str, optional
        The service's URL; default ``HOCKLE_PUBLIC_URL`` or
        ``http://HOCKLE_HOST:HOCKLE_PORT``.
    api_key : str, optional
        Sent as ``Authorization: Bearer <key>`` on every request; default the environment's
        ``HOCKLE_API_KEY``; none for a service without keys. An empty string sends no key
        even when the environment has one.
    timeout : float
        Seconds for each request.
    transport : httpx.BaseTransport, optional
        Another transport (the tests' in-process app).
    headers : dict, optional
        Headers sent with every request.

    Examples
    --------
    >>> with HockleClient("http://127.0.0.1:8000") as client:       # doctest: +SKIP
    ...     job = client.wait(client.submit("cases/goyal-writhing.yaml").id)
    ...     ds = client.dataset(job.id)
    """

    def __init__(self, base_url: str | None = None, *, api_key: str | None = None,
                 timeout: float = 30.0, transport: httpx.BaseTransport | None = None,
                 headers: dict | None = None):
        if base_url is None:
            from .settings import get_settings

            base_url = get_settings().base_url
        self.base_url = base_url.rstrip("/")
        if api_key is None:
            api_key = os.environ.get("HOCKLE_API_KEY")
        headers = dict(headers or {})
        if api_key and api_key.strip():
            headers["Authorization"] = f"Bearer {api_key.strip()}"
        self._http = httpx.Client(base_url=self.base_url, timeout=timeout, transport=transport,
                                  headers=headers)

    def __enter__(self) -> "HockleClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Close the client's connections."""
        self._http.close()

    # --- plumbing ------------------------------------------------------------------------------
    def _request(self, method: str, url: str, **kwargs) -> httpx.Response:
        response = self._http.request(method, url, **kwargs)
        if response.status_code >= 400:
            try:
                problem = response.json()
            except ValueError:
                problem = {"title": response.reason_phrase, "detail": response.text[:500]}
            raise HockleAPIError(response.status_code, problem)
        return response

    # --- jobs ----------------------------------------------------------------------------------
    def submit(self, case, *, idempotency_key: str | None = None, fresh: bool = False,
               time_limit: float | None = None) -> JobStatus:
        """Submit a case as a job (``POST /v1/jobs``).

        Parameters
        ----------
        case : str or os.PathLike or mapping or solver.Case
            A case file, a mapping or a validated case.
        idempotency_key : str, optional
            The same key with the same case answers with the same job.
        fresh : bool
            Run it even if an identical case already ran successfully (otherwise that job is
            answered, marked ``reused``).
        time_limit : float, optional
            The job's hard time limit, s, up to the service's ``HOCKLE_TIME_LIMIT_MAX``;
            default derived from the case's size and contact.

        Returns
        -------
        service.schemas.JobStatus
            The job's status.

        Raises
        ------
        HockleAPIError
            422 naming each bad field of an invalid case.
        """
        body, content_type = case_payload(case)
        headers = {"Content-Type": content_type}
        if idempotency_key:
            headers["Idempotency-Key"] = idempotency_key
        params: dict[str, Any] = {"fresh": "true"} if fresh else {}
        if time_limit is not None:
            params["time_limit"] = time_limit
        response = self._request("POST", "/v1/jobs", content=body, headers=headers, params=params)
        return JobStatus.model_validate(response.json())

    def submit_continuation(self, case, parameter: str, to: float, *,
                            time: float | None = None, switch: bool = False,
                            max_points: int | None = None, step: float | None = None,
                            shapes_every: int | None = None, stability: bool | None = None,
                            idempotency_key: str | None = None, fresh: bool = False,
                            time_limit: float | None = None) -> JobStatus:
        """Submit a continuation job (``POST /v1/continuations``; docs/statics.md).

        The static branch of ``case`` while the scalar at the dotted ``parameter`` goes to
        ``to``; :meth:`wait` and :meth:`download` as for any job, the result being the
        branch dataset.

        Parameters
        ----------
        case : str or os.PathLike or mapping or solver.Case
            A case file, a mapping or a validated case.
        parameter : str
            The dotted path of the scalar.
        to : float
            The value to continue to.
        time, switch, max_points, step, shapes_every, stability : optional
            The options of :func:`hockle.api.continue_branch`; left out, the service's
            defaults.
        idempotency_key, fresh, time_limit : optional
            As for :meth:`submit`.

        Returns
        -------
        service.schemas.JobStatus
            The job's status (``kind`` ``continuation``).
        """
        options: dict[str, Any] = {"parameter": parameter, "to": to, "switch": switch}
        for key, value in (("time", time), ("max_points", max_points), ("step", step),
                           ("shapes_every", shapes_every), ("stability", stability)):
            if value is not None:
                options[key] = value
        body = json.dumps({"case": case_document(case), "continuation": options}).encode()
        headers = {"Content-Type": "application/json"}
        if idempotency_key:
            headers["Idempotency-Key"] = idempotency_key
        params: dict[str, Any] = {"fresh": "true"} if fresh else {}
        if time_limit is not None:
            params["time_limit"] = time_limit
        response = self._request("POST", "/v1/continuations", content=body, headers=headers,
                                 params=params)
        return JobStatus.model_validate(response.json())

    def get(self, job_id: str) -> JobStatus:
        """A job's status: state, progress, events, result links.

        Parameters
        ----------
        job_id : str

        Returns
        -------
        service.schemas.JobStatus
        """
        return JobStatus.model_validate(self._request("GET", f"/v1/jobs/{job_id}").json())

    def list(self, *, status: str | list[str] | None = None, page_size: int = 50,
             page_token: str | None = None) -> JobList:
        """One page of the jobs, newest first.

        Parameters
        ----------
        status : str or list of str, optional
            Only jobs in these states.
        page_size : int
            Jobs per page.
        page_token : str, optional
            The ``next_page_token`` of the page before.

        Returns
        -------
        service.schemas.JobList
        """
        params: dict[str, Any] = {"page_size": page_size}
        if status:
            params["status"] = status if isinstance(status, str) else ",".join(status)
        if page_token:
            params["page_token"] = page_token
        return JobList.model_validate(self._request("GET", "/v1/jobs", params=params).json())

    def iter_jobs(self, **kwargs) -> Iterator[JobStatus]:
        """Every job, page after page.

        Parameters
        ----------
        **kwargs
            ``status`` and ``page_size``, as for :meth:`list`.

        Yields
        ------
        service.schemas.JobStatus
        """
        token = None
        while True:
            page = self.list(page_token=token, **kwargs)
            yield from page.jobs
            token = page.next_page_token
            if not token:
                return

    def dismiss(self, job_id: str) -> JobStatus:
        """Dismiss a queued or running job (a running one stops within one time step).

        Parameters
        ----------
        job_id : str

        Returns
        -------
        service.schemas.JobStatus

        Raises
        ------
        HockleAPIError
            409 for a job that has finished.
        """
        return JobStatus.model_validate(self._request("DELETE", f"/v1/jobs/{job_id}").json())

    def spec(self, job_id: str) -> dict[str, Any]:
        """The job's case, canonical (defaults filled in).

        Parameters
        ----------
        job_id : str

        Returns
        -------
        dict
        """
        return self._request("GET", f"/v1/jobs/{job_id}/spec").json()

    def wait(self, job_id: str, *, timeout: float | None = None, poll_interval: float = 0.5,
             on_progress: Callable[[JobStatus], None] | None = None) -> JobStatus:
        """Poll until the job is terminal (successful, failed or dismissed).

        Parameters
        ----------
        job_id : str
        timeout : float, optional
            Give up after that many seconds.
        poll_interval : float
            Seconds between polls.
        on_progress : callable, optional
            Called with each status.

        Returns
        -------
        service.schemas.JobStatus
            The terminal status.

        Raises
        ------
        TimeoutError
            Still not terminal after ``timeout``.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            job = self.get(job_id)
            if on_progress is not None:
                on_progress(job)
            if job.state in TERMINAL:
                return job
            if deadline is not None and time.monotonic() > deadline:
                raise TimeoutError(f"job {job_id} is still {job.state} after {timeout} s")
            time.sleep(poll_interval)

    # --- results -------------------------------------------------------------------------------
    def download(self, job_id: str, path: str | os.PathLike) -> Path:
        """Save the job's NetCDF result (written to a temporary name, then renamed).

        Parameters
        ----------
        job_id : str
        path : str or os.PathLike

        Returns
        -------
        pathlib.Path

        Raises
        ------
        HockleAPIError
            404 ``result-not-ready`` while there is none.
        """
        path = Path(path)
        tmp = path.with_name(path.name + ".part")
        with self._http.stream("GET", f"/v1/jobs/{job_id}/results") as response:
            if response.status_code >= 400:
                response.read()
                raise HockleAPIError(response.status_code, _problem(response))
            with open(tmp, "wb") as fh:
                for chunk in response.iter_bytes():
                    fh.write(chunk)
        os.replace(tmp, path)
        return path

    def dataset(self, job_id: str):
        """The job's result, read into memory.

        Parameters
        ----------
        job_id : str

        Returns
        -------
        xarray.Dataset
        """
        import xarray as xr

        with tempfile.TemporaryDirectory(prefix="hockle-") as tmp:
            path = self.download(job_id, Path(tmp) / f"{job_id}.nc")
            with xr.open_dataset(path, engine="netcdf4") as ds:
                return ds.load()

    def variables(self, job_id: str) -> VariableList:
        """The result's variables with their dimensions and units.

        Parameters
        ----------
        job_id : str

        Returns
        -------
        service.schemas.VariableList
        """
        return VariableList.model_validate(
            self._request("GET", f"/v1/jobs/{job_id}/results/variables").json())

    def variable(self, job_id: str, name: str, **selectors: Any) -> VariableSlice:
        """A slice of one result variable, cut by the server.

        Parameters
        ----------
        job_id : str
        name : str
            The variable (``kappa``, ``position``, ...).
        **selectors
            Per dimension a value (nearest for float coordinates), a range ``"a:b"`` or a
            :class:`slice`, or a list: ``time="0:1"``, ``s=0.5``, ``component=3``,
            ``xyz="z"`` (docs/service.md).

        Returns
        -------
        service.schemas.VariableSlice

        Raises
        ------
        HockleAPIError
            422 naming the dimension of a selector out of range, or ``slice-too-large``.
        """
        params = {k: _selector(v) for k, v in selectors.items() if v is not None}
        return VariableSlice.model_validate(
            self._request("GET", f"/v1/jobs/{job_id}/results/variables/{name}",
                          params=params).json())

    def summary(self, job_id: str) -> Summary:
        """The result's scalar time series (energies, twist, writhe, contacts, ...).

        Parameters
        ----------
        job_id : str

        Returns
        -------
        service.schemas.Summary
        """
        return Summary.model_validate(self._request("GET", f"/v1/jobs/{job_id}/summary").json())

    def health(self) -> Health:
        """The service's readiness: registry, broker, workers, version.

        Returns
        -------
        service.schemas.Health
            Also when the service answers 503 (not ready).
        """
        response = self._http.get("/v1/health")
        if response.status_code not in (200, 503):
            raise HockleAPIError(response.status_code, _problem(response))
        return Health.model_validate(response.json())


    # --- sweeps --------------------------------------------------------------------------------
    def sweep(self, base, parameters: Mapping[str, Any], *, combine: str = "grid",
              wait: bool = False, fresh: bool = False, time_limit: float | None = None,
              name: str | None = None, timeout: float | None = None,
              poll_interval: float = 1.0, on_progress: Callable | None = None):
        """Submit a parameter sweep (``POST /v1/sweeps``).

        Parameters
        ----------
        base : str or os.PathLike or mapping or solver.Case
            The case every member starts from.
        parameters : mapping
            ``{PATH: [values]}``, PATH a dotted path into the case
            (``"boundary.end.translation.2.force"``).
        combine : {"grid", "zip"}
            Every combination of the values, or the values side by side.
        wait : bool
            Return once every member has finished (then :meth:`sweep_dataset` gives the
            combined dataset).
        fresh, time_limit : optional
            As for :meth:`submit`, for every member.
        name : str, optional
            The sweep's name.
        timeout, poll_interval, on_progress : optional
            With ``wait``, as for :meth:`wait_sweep`.

        Returns
        -------
        service.sweeps.SweepStatus

        Raises
        ------
        HockleAPIError
            422 naming the member and the field of a bad member value; nothing is queued.
        """
        from .sweeps import SweepStatus

        body: dict[str, Any] = {"base": case_document(base), "combine": combine,
                                "parameters": {str(k): list(v) for k, v in parameters.items()}}
        if name is not None:
            body["name"] = name
        params: dict[str, Any] = {"fresh": "true"} if fresh else {}
        if time_limit is not None:
            params["time_limit"] = time_limit
        response = self._request("POST", "/v1/sweeps", json=body, params=params)
        status = SweepStatus.model_validate(response.json())
        if wait:
            status = self.wait_sweep(status.id, timeout=timeout, poll_interval=poll_interval,
                                     on_progress=on_progress)
        return status

    def get_sweep(self, sweep_id: str):
        """The sweep's state, progress and members.

        Parameters
        ----------
        sweep_id : str

        Returns
        -------
        service.sweeps.SweepStatus
        """
        from .sweeps import SweepStatus

        return SweepStatus.model_validate(self._request("GET", f"/v1/sweeps/{sweep_id}").json())

    def dismiss_sweep(self, sweep_id: str):
        """Dismiss the sweep's queued and running members.

        Parameters
        ----------
        sweep_id : str

        Returns
        -------
        service.sweeps.SweepStatus
        """
        from .sweeps import SweepStatus

        return SweepStatus.model_validate(
            self._request("DELETE", f"/v1/sweeps/{sweep_id}").json())

    def wait_sweep(self, sweep_id: str, *, timeout: float | None = None,
                   poll_interval: float = 1.0, on_progress: Callable | None = None):
        """Poll until every member of the sweep has finished.

        Parameters
        ----------
        sweep_id : str
        timeout : float, optional
            Give up after that many seconds.
        poll_interval : float
            Seconds between polls.
        on_progress : callable, optional
            Called with each status.

        Returns
        -------
        service.sweeps.SweepStatus

        Raises
        ------
        TimeoutError
            Members still running after ``timeout``.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            status = self.get_sweep(sweep_id)
            if on_progress is not None:
                on_progress(status)
            if status.terminal:
                return status
            if deadline is not None and time.monotonic() > deadline:
                raise TimeoutError(f"sweep {sweep_id} is still {status.state} after {timeout} s")
            time.sleep(poll_interval)

    def download_sweep(self, sweep_id: str, path: str | os.PathLike,
                       fields: str | list[str] | None = None) -> Path:
        """Save the combined NetCDF dataset of a finished sweep.

        Parameters
        ----------
        sweep_id : str
        path : str or os.PathLike
        fields : str or list of str, optional
            Full fields (``["position"]``) added to the scalar series and event times.

        Returns
        -------
        pathlib.Path
        """
        params = {}
        if fields:
            params["fields"] = fields if isinstance(fields, str) else ",".join(fields)
        path = Path(path)
        tmp = path.with_name(path.name + ".part")
        with self._http.stream("GET", f"/v1/sweeps/{sweep_id}/results",
                               params=params) as response:
            if response.status_code >= 400:
                response.read()
                raise HockleAPIError(response.status_code, _problem(response))
            with open(tmp, "wb") as fh:
                for chunk in response.iter_bytes():
                    fh.write(chunk)
        os.replace(tmp, path)
        return path

    def sweep_dataset(self, sweep_id: str, fields: str | list[str] | None = None):
        """The combined dataset of a finished sweep, read into memory.

        Parameters
        ----------
        sweep_id : str
        fields : str or list of str, optional
            As for :meth:`download_sweep`.

        Returns
        -------
        xarray.Dataset
        """
        import xarray as xr

        with tempfile.TemporaryDirectory(prefix="hockle-") as tmp:
            path = self.download_sweep(sweep_id, Path(tmp) / f"{sweep_id}.nc", fields)
            with xr.open_dataset(path, engine="netcdf4") as ds:
                return ds.load()

def _selector(value: Any) -> str:
    if isinstance(value, slice):
        lo = "" if value.start is None else value.start
        hi = "" if value.stop is None else value.stop
        return f"{lo}:{hi}"
    if isinstance(value, (list, tuple)):
        return ",".join(str(v) for v in value)
    return str(value)


def _problem(response: httpx.Response) -> dict[str, Any]:
    try:
        return response.json()
    except ValueError:
        return {"title": response.reason_phrase, "detail": response.text[:500]}
