"""Reading and validating a submitted case: the same pydantic ``Case`` the CLI uses.

Every refusal is a :class:`~service.problems.ProblemError` whose ``errors`` name each bad field by
its path (``rod.youngs_modulus``) and say what is allowed; unknown fields list the allowed ones.
"""
from __future__ import annotations

import json
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import yaml
from pydantic import ValidationError
from yaml.composer import ComposerError
from yaml.events import (AliasEvent, MappingEndEvent, MappingStartEvent, ScalarEvent,
                         SequenceEndEvent, SequenceStartEvent, StreamEndEvent)
from yaml.nodes import MappingNode, ScalarNode, SequenceNode

from solver.case import allowed_fields  # noqa: F401  (its home is solver.case)

from .problems import ProblemError, _loc

MAX_BODY_BYTES = 4 * 1024 * 1024
#: the deepest nesting of lists and mappings a body may have (the deepest a case spec needs
#: is 9 levels: a sweep's base, boundary, end, translation, an item, a list of conditions, a
#: condition, a table, its times)
MAX_NESTING = 32
#: the most nodes (scalars, lists, mappings) a body may hold, a YAML alias counted as the
#: nodes it stands for: what a body of MAX_BODY_BYTES could hold without aliases (a value
#: and its separator take two bytes at least), so that aliases make no body larger
MAX_NODES = MAX_BODY_BYTES // 2
#: the longest integer literal read (the largest finite double, ~1.8e308, has 309 digits;
#: Python converts at most 4,300)
MAX_INT_DIGITS = 309
#: seconds one body may take to parse (HOCKLE_BODY_PARSE_TIMEOUT's default)
PARSE_TIMEOUT = 2.0
#: bodies parsed at once on threads of the API process (JSON, and YAML up to
#: YAML_IN_PROCESS bytes)
PARSE_THREADS = 4
#: YAML bodies larger than this are parsed in a parse process (PARSE_PROCESSES of them,
#: niced): PyYAML's node graph of a large body costs the API process's interpreter seconds of
#: CPU, its garbage collector's passes and a long deallocation, all holding the lock that the
#: event loop needs too (liveness took up to 340 ms under four 3.4-MB bodies parsed on
#: threads); a case spec written by hand is a few kB
YAML_IN_PROCESS = 64 * 1024
PARSE_PROCESSES = 2
#: the budget's clock is read every this many nodes
_TICK = 256
YAML_TYPES = ("application/yaml", "application/x-yaml", "text/yaml", "text/x-yaml")


_PARSERS = ThreadPoolExecutor(max_workers=PARSE_THREADS, thread_name_prefix="hockle-parse")


def too_large() -> ProblemError:
    """The 413 problem of a body over MAX_BODY_BYTES."""
    return ProblemError(413, "body-too-large", "Request body too large",
                        f"a case spec may be at most {MAX_BODY_BYTES} bytes")


async def read_body(request) -> bytes:
    """The request body, read in chunks and refused (413) as soon as it exceeds
    MAX_BODY_BYTES, or at once when Content-Length says so: a large body is never held
    whole (eight concurrent 50 MB POSTs took the API from 183 to 767 MB when bodies were
    read before the check)."""
    declared = request.headers.get("content-length")
    if declared is not None:
        try:
            if int(declared) > MAX_BODY_BYTES:
                raise too_large()
        except ValueError:
            raise ProblemError(400, "malformed-body", "Malformed request body",
                               "the Content-Length header is not a number") from None
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > MAX_BODY_BYTES:
            raise too_large()
        chunks.append(chunk)
    return b"".join(chunks)


def parse_body(body: bytes, content_type: str | None,
               timeout: float = PARSE_TIMEOUT) -> Any:
    """JSON (default) or YAML (by Content-Type) to Python data, within a budget:

    * at most :data:`MAX_NODES` nodes (scalars, lists, mappings), a YAML alias counted as
      the nodes it expands to, so that an alias bomb is refused before anything expands it
      (its aliases are composed as references to one node, sized once each);
    * lists and mappings nested at most :data:`MAX_NESTING` deep (also through aliases);
    * integer literals of at most :data:`MAX_INT_DIGITS` digits (Python refuses to convert
      more than 4,300; a double holds at most 309);
    * ``timeout`` seconds of parsing, checked as it goes.

    Linear in the body's size. Problems: 400 (not JSON/YAML), 413 (the budget), 415, 422
    (nesting, an integer too long: naming where). Blocking: call it off the event loop
    (:func:`parse_request`)."""
    if len(body) > MAX_BODY_BYTES:
        raise too_large()
    media = (content_type or "application/json").split(";")[0].strip().lower()
    if not body.strip():
        raise ProblemError(422, "invalid-case", "Invalid case spec", "the request body is empty",
                           errors=[{"loc": "", "msg": "a case spec (JSON object) is required",
                                    "type": "missing"}])
    budget = _Budget(timeout)
    if media in YAML_TYPES:
        return _parse_yaml(body, budget)
    if media not in ("application/json", "text/json") and not media.endswith("+json"):
        raise ProblemError(415, "unsupported-media-type", "Unsupported media type",
                           f"send the case as application/json or application/yaml, not {media}")
    try:
        data = json.loads(body, parse_int=_json_int)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ProblemError(400, "malformed-body", "Malformed request body",
                           f"the body is not valid JSON: {exc}") from None
    except RecursionError:
        raise too_deep("") from None
    return check_nesting(data, budget=budget)


async def parse_request(request, timeout: float = PARSE_TIMEOUT) -> Any:
    """The request's body (:func:`read_body`), parsed by :func:`parse_body` never on the
    event loop, so that liveness and every other request go on while a body is parsed: on a
    thread of :data:`_PARSERS` (at most :data:`PARSE_THREADS` at once), or, for a YAML body
    over :data:`YAML_IN_PROCESS` bytes, in a parse process (:func:`_parse_elsewhere`), each
    within its own ``timeout``."""
    import asyncio

    body = await read_body(request)
    content_type = request.headers.get("content-type")
    media = (content_type or "").split(";")[0].strip().lower()
    if media in YAML_TYPES and len(body) > YAML_IN_PROCESS:
        return await _parse_elsewhere(body, content_type, timeout)
    loop = asyncio.get_running_loop()
    return await loop.run_in_executor(_PARSERS, parse_body, body, content_type, timeout)


_PROCESSES: list = []
_PROCESSES_LOCK = threading.Lock()
#: seconds a parse process may take beyond the body's budget (its start: importing this
#: module, about a second) before it is killed and the body refused
_PROCESS_GRACE = 15.0


def _process_pool():
    with _PROCESSES_LOCK:
        if not _PROCESSES:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            # spawned, not forked: the API process has threads and open connections
            _PROCESSES.append(ProcessPoolExecutor(
                PARSE_PROCESSES, mp_context=multiprocessing.get_context("spawn"),
                initializer=_parse_process_started))
        return _PROCESSES[0]


def _drop_process_pool(pool) -> None:
    """Kill the parse processes of ``pool`` (one overran its budget); the next large body
    starts new ones."""
    with _PROCESSES_LOCK:
        if _PROCESSES and _PROCESSES[0] is pool:
            _PROCESSES.clear()
    for process in list(getattr(pool, "_processes", {}).values()):
        process.kill()
    pool.shutdown(wait=False, cancel_futures=True)


def _parse_process_started() -> None:
    """In each parse process: a lower CPU priority than the API's (as the embedded worker)."""
    try:
        os.nice(10)
    except OSError:
        pass


def _parse_in_process(body: bytes, content_type: str | None, timeout: float):
    """:func:`parse_body` in a parse process: ``("ok", data)`` or ``("problem", ...)`` (a
    ProblemError does not pickle back by itself)."""
    try:
        return ("ok", parse_body(body, content_type, timeout))
    except ProblemError as exc:
        return ("problem", exc.status, exc.slug, exc.title, exc.detail, exc.errors, exc.headers)


async def _parse_elsewhere(body: bytes, content_type: str | None, timeout: float) -> Any:
    import asyncio
    from concurrent.futures.process import BrokenProcessPool

    pool = _process_pool()
    loop = asyncio.get_running_loop()
    try:
        answer = await asyncio.wait_for(
            loop.run_in_executor(pool, _parse_in_process, body, content_type, timeout),
            timeout + _PROCESS_GRACE)
    except (asyncio.TimeoutError, BrokenProcessPool):
        _drop_process_pool(pool)
        raise _Budget(timeout).overrun() from None
    if answer[0] == "ok":
        return answer[1]
    _, status, slug, title, detail, errors, headers = answer
    raise ProblemError(status, slug, title, detail, errors=errors, headers=headers)


class _TooLongInteger:
    """A JSON integer literal of more than MAX_INT_DIGITS digits, kept unconverted until
    :func:`check_nesting` finds where it is."""

    __slots__ = ("digits",)

    def __init__(self, digits: int):
        self.digits = digits


def _json_int(text: str):
    digits = len(text.lstrip("+-"))
    return int(text) if digits <= MAX_INT_DIGITS else _TooLongInteger(digits)


def _long_integer(loc: str, digits: int) -> ProblemError:
    msg = (f"an integer literal of {digits} digits: more than any finite double holds "
           f"(at most {MAX_INT_DIGITS} digits, about 1.8e308) and more than this service "
           "reads; give the value as a number in SI units")
    return ProblemError(422, "invalid-case", "Invalid case spec", msg,
                        errors=[{"loc": loc, "msg": msg, "type": "integer_too_long"}])


class _Budget:
    """The time left to parse one body (checked every :data:`_TICK` steps)."""

    def __init__(self, timeout: float):
        self.timeout = float(timeout)
        self.deadline = time.monotonic() + self.timeout
        self.steps = 0

    def tick(self) -> None:
        self.steps += 1
        if self.steps % _TICK == 0 and time.monotonic() > self.deadline:
            raise self.overrun()

    def overrun(self) -> ProblemError:
        return ProblemError(413, "body-too-large", "Request body too complex",
                            f"the body took more than {self.timeout:g} s to parse "
                            "(HOCKLE_BODY_PARSE_TIMEOUT); a case spec parses in "
                            "milliseconds: send a smaller body, or JSON instead of YAML",
                            errors=[{"loc": "", "type": "parse_time_exceeded",
                                     "msg": f"not parsed within {self.timeout:g} s"}])


def _too_many_nodes(loc: str) -> ProblemError:
    msg = (f"the body expands to more than {MAX_NODES} values here (YAML aliases counted "
           "as the values they stand for): more than a body of the largest accepted size "
           "could hold")
    return ProblemError(413, "body-too-large", "Request body too large",
                        "the body expands to more values than this service accepts",
                        errors=[{"loc": loc, "msg": msg, "type": "too_many_nodes"}])


def _parse_yaml(body: bytes, budget: _Budget) -> Any:
    """YAML to Python data within ``budget``: composed event by event (libyaml's parser
    where PyYAML has it) by :class:`_YamlComposer`, which sizes every node once (an alias
    counts as the nodes it stands for) and refuses an alias bomb, a recursive alias, deep
    nesting or a long integer before anything is constructed; then constructed with the
    rules of ``hockle validate`` (YAML 1.2 floats, duplicate keys refused), aliases as
    shared references."""
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ProblemError(400, "malformed-body", "Malformed request body",
                           f"the body is not valid YAML: not UTF-8 text: {exc}") from None
    loader = _yaml_loader()(text)
    try:
        node = _YamlComposer(loader, budget).document()
        if node is None:
            return None
        return loader.construct_document(node)
    except yaml.YAMLError as exc:
        raise ProblemError(400, "malformed-body", "Malformed request body",
                           "the body is not valid YAML",
                           errors=[{"loc": "", "msg": f"YAML syntax error: {exc}",
                                    "type": "yaml_syntax"}]) from None
    finally:
        loader.dispose()


_LOADERS: list = []


def _yaml_loader():
    """The loader class: the case files' rules (:class:`solver.case._YamlLoader`) on
    libyaml's event parser where PyYAML was built with it, else PyYAML's own; construction
    checks the parse's deadline (``_budget``)."""
    if _LOADERS:
        return _LOADERS[0]
    from yaml.constructor import SafeConstructor
    from yaml.resolver import Resolver

    from solver.case import _YamlLoader

    class Loader(_YamlLoader):
        _budget: _Budget | None = None

        def construct_object(self, node, deep=False):
            if self._budget is not None:
                self._budget.tick()
            return super().construct_object(node, deep=deep)

    if getattr(yaml, "__with_libyaml__", False):
        from yaml._yaml import CParser

        class CLoader(CParser, Loader):
            def __init__(self, stream):
                CParser.__init__(self, stream)
                SafeConstructor.__init__(self)
                Resolver.__init__(self)

        Loader = CLoader  # noqa: N806
    _LOADERS.append(Loader)
    return Loader


class _YamlComposer:
    """PyYAML's composer (yaml.composer.Composer) with a budget: every node is sized as it
    is composed (``_n``: nodes it expands to, ``_h``: lists and mappings nested in it), an
    alias adds the size of the node it names, and the running total, the nesting and the
    time are checked at every node. Linear in the number of events."""

    def __init__(self, loader, budget: _Budget):
        self.loader = loader
        self.budget = budget
        self.total = 0
        self.anchors: dict = {}
        loader._budget = budget

    def document(self):
        """The root node of the body's single document (None for an empty stream)."""
        loader = self.loader
        loader.get_event()      # StreamStartEvent
        node = None
        if not loader.check_event(StreamEndEvent):
            loader.get_event()  # DocumentStartEvent
            node = self.node((), 0)
            loader.get_event()  # DocumentEndEvent
            if not loader.check_event(StreamEndEvent):
                event = loader.get_event()
                raise ComposerError("expected a single document in the stream", None,
                                    "but found another document", event.start_mark)
        loader.get_event()      # StreamEndEvent
        return node

    def _count(self, n: int, path: tuple) -> None:
        self.total += n
        if self.total > MAX_NODES:
            raise _too_many_nodes(_loc(path))

    def node(self, path: tuple, depth: int):
        """The node at ``path`` inside ``depth`` lists and mappings."""
        loader = self.loader
        self.budget.tick()
        if loader.check_event(AliasEvent):
            event = loader.get_event()
            node = self.anchors.get(event.anchor)
            if node is None:
                raise ComposerError(None, None, f"found undefined alias {event.anchor!r}",
                                    event.start_mark)
            if not hasattr(node, "_n"):
                msg = (f"the alias *{event.anchor} names a list or mapping that contains it: "
                       "it would expand without end")
                raise ProblemError(422, "invalid-case", "Invalid case spec", msg, errors=[
                    {"loc": _loc(path), "msg": msg, "type": "recursive_alias"}])
            if depth + node._h > MAX_NESTING:
                raise too_deep(_loc(path))
            self._count(node._n, path)
            return node
        event = loader.peek_event()
        anchor = event.anchor
        if anchor is not None and anchor in self.anchors:
            raise ComposerError("found duplicate anchor %r; first occurrence" % anchor,
                                self.anchors[anchor].start_mark, "second occurrence",
                                event.start_mark)
        self._count(1, path)
        if loader.check_event(ScalarEvent):
            event = loader.get_event()
            tag = event.tag
            if tag is None or tag == "!":
                tag = loader.resolve(ScalarNode, event.value, event.implicit)
            if tag == "tag:yaml.org,2002:int":
                digits = len(event.value.replace("_", "").lstrip("+-"))
                if digits > MAX_INT_DIGITS:
                    raise _long_integer(_loc(path), digits)
            node = ScalarNode(tag, event.value, event.start_mark, event.end_mark,
                              style=event.style)
            node._n, node._h = 1, 0
            if anchor is not None:
                self.anchors[anchor] = node
            return node
        if depth + 1 > MAX_NESTING:
            raise too_deep(_loc(path))
        if loader.check_event(SequenceStartEvent):
            start = loader.get_event()
            tag = start.tag
            if tag is None or tag == "!":
                tag = loader.resolve(SequenceNode, None, start.implicit)
            node = SequenceNode(tag, [], start.start_mark, None, flow_style=start.flow_style)
            if anchor is not None:
                self.anchors[anchor] = node
            size, height = 1, 0
            while not loader.check_event(SequenceEndEvent):
                item = self.node(path + (len(node.value),), depth + 1)
                node.value.append(item)
                size += item._n
                height = max(height, item._h)
            node.end_mark = loader.get_event().end_mark
            node._n, node._h = size, height + 1
            return node
        if loader.check_event(MappingStartEvent):
            start = loader.get_event()
            tag = start.tag
            if tag is None or tag == "!":
                tag = loader.resolve(MappingNode, None, start.implicit)
            node = MappingNode(tag, [], start.start_mark, None, flow_style=start.flow_style)
            if anchor is not None:
                self.anchors[anchor] = node
            size, height = 1, 0
            while not loader.check_event(MappingEndEvent):
                key = self.node(path + ("?",), depth + 1)
                name = key.value if isinstance(key, ScalarNode) else "?"
                value = self.node(path + (name,), depth + 1)
                node.value.append((key, value))
                size += key._n + value._n
                height = max(height, key._h, value._h)
            node.end_mark = loader.get_event().end_mark
            node._n, node._h = size, height + 1
            return node
        raise ComposerError(None, None, f"unexpected event {event!r}", event.start_mark)


def too_deep(loc: str) -> ProblemError:
    """The 422 problem of a body nested deeper than MAX_NESTING (at ``loc``)."""
    msg = (f"lists and mappings nested more than {MAX_NESTING} deep here; a case spec or "
           "a sweep nests at most about 10 levels")
    return ProblemError(422, "nesting-too-deep", "Body nested too deeply",
                        f"the body nests lists or mappings more than {MAX_NESTING} deep",
                        errors=[{"loc": loc, "msg": msg, "type": "nesting_too_deep"}])


def check_nesting(data: Any, limit: int = MAX_NESTING, budget: "_Budget | None" = None) -> Any:
    """``data`` unchanged, or a 422 problem naming the first place where lists and mappings
    nest deeper than ``limit`` (``nesting_too_deep``) or where a JSON integer literal was too
    long to convert (``integer_too_long``). Iterative: no recursion limit to meet, and
    nothing deeper reaches the validation (a sweep value 500 deep ended in a RecursionError
    in ``copy.deepcopy``). Linear for a tree (what JSON parses to); with ``budget``, within
    its time."""
    stack: list[tuple[Any, int, tuple]] = [(data, 1, ())]
    while stack:
        node, depth, path = stack.pop()
        if budget is not None:
            budget.tick()
        if isinstance(node, _TooLongInteger):
            raise _long_integer(_loc(path), node.digits)
        if isinstance(node, dict):
            items = node.items()
        elif isinstance(node, list):
            items = enumerate(node)
        else:
            continue
        if depth > limit:
            raise too_deep(_loc(path))
        stack.extend((value, depth + 1, path + (key,)) for key, value in items
                     if isinstance(value, (dict, list, _TooLongInteger)))
    return data


def validate_case(data: Any, max_case_size: int):
    """Return the validated ``Case`` or raise a 422 problem listing every bad field."""
    from solver.case import Case, format_validation_errors

    if not isinstance(data, dict):
        raise ProblemError(422, "invalid-case", "Invalid case spec",
                           "a case spec must be a JSON object",
                           errors=[{"loc": "", "msg": f"must be an object (mapping of fields), "
                                    f"got {type(data).__name__}", "type": "dict_type"}])
    try:
        case = Case.model_validate(data)
    except ValidationError as exc:
        errors = format_validation_errors(exc)   # unknown fields list the allowed ones
        raise ProblemError(422, "invalid-case", "Invalid case spec",
                           f"{len(errors)} field(s) of the case spec are not valid",
                           errors=errors) from None
    if case.initial.from_result is not None and case.initial.from_result.file is not None:
        # a path on this server is never read for a request (the CLI and the Python API
        # read the file themselves: hockle.io.read_start_state); over HTTP an earlier job
        # of the same owner is named by its id (start_from_job)
        msg = ("a result file is not accepted over HTTP: the service reads no paths on its "
               "machine; give initial.from_result.job, the id of an earlier successful job "
               "of yours, or run the case with the CLI or the Python API")
        raise ProblemError(422, "invalid-case", "Invalid case spec", msg, errors=[
            {"loc": "initial.from_result.file", "msg": msg, "type": "not_accepted_over_http"}])
    size = case.grid_points * case.n_steps
    if size > max_case_size:
        msg = (f"case too large: {case.grid_points} grid points x {case.n_steps} time steps = "
               f"{size} exceeds this service's limit of {max_case_size}; lower numerics.n_segments "
               f"(or raise numerics.ds), or the steps t_end / dt (lower numerics.t_end or raise "
               f"numerics.dt)")
        raise ProblemError(422, "case-too-large", "Case too large", msg, errors=[
            {"loc": "numerics.n_segments", "msg": msg, "type": "case_too_large"},
            {"loc": "numerics.t_end", "msg": msg, "type": "case_too_large"},
            {"loc": "numerics.dt", "msg": msg, "type": "case_too_large"},
        ])
    return case



def start_from_job(case, registry, owner: str | None):
    """The :class:`solver.initial.StartState` of a case whose ``initial.from_result``
    names an earlier job (``job``), or None for any other case.

    The job must be the caller's (``owner``, :func:`service.auth.caller`; None, a service
    without API keys: any job), have finished successfully and still hold its result,
    which must be of the same rod with ``time`` among its output times
    (:func:`solver.results.start_state_from`). Another owner's job is answered exactly
    as an unknown id, so that ids cannot be probed. Raises a 422 :class:`ProblemError`
    naming ``initial.from_result.job`` or ``initial.from_result.time``."""
    from solver.case import CaseError
    from solver.results import start_state_from

    from .registry import SUCCESSFUL
    from .store import open_result

    spec = case.initial.from_result
    if spec is None or spec.job is None:
        return None

    def refuse(loc, etype, msg):
        return ProblemError(422, "invalid-case", "Invalid case spec", msg,
                            errors=[{"loc": loc, "msg": msg, "type": etype}])

    loc = "initial.from_result.job"
    job = registry.get(spec.job)
    if job is None or (owner is not None and job.owner != owner):
        raise refuse(loc, "unknown_job", f"no job with id {spec.job} of yours")
    if (job.kind or "dynamic") != "dynamic":
        raise refuse(loc, "job_not_dynamic",
                     f"job {spec.job} is a {job.kind} job: its result is a branch, not a run "
                     "to start from (hockle.api.equilibrium_start starts from a branch point)")
    if job.state != SUCCESSFUL or not job.result_path:
        raise refuse(loc, "job_not_successful",
                     f"job {spec.job} is {job.state}, not successful: a start from an "
                     "earlier job needs its complete result")
    try:
        with open_result(job.result_path) as ds:
            return start_state_from(ds, case, f"the result of job {spec.job}", "job")
    except CaseError as exc:
        raise ProblemError(422, "invalid-case", "Invalid case spec", exc.errors[0]["msg"],
                           errors=[{"loc": e["loc"], "msg": e["msg"], "type": e["type"]}
                                   for e in exc.errors]) from None
    except OSError:
        raise refuse(loc, "result_gone",
                     f"the result of job {spec.job} is no longer stored") from None
