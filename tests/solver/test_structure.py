"""The solver's shape (issue 36): the time loop a screen long, no long functions outside
the compiled kernels, and the interface between step control and the step
(``RodRun.try_step`` -> ``Attempt``). docs/developer.md draws it. No import circles, in
solver/ or anywhere: tests/test_layers.py."""
from __future__ import annotations

import ast
import copy
import importlib
from pathlib import Path

import numpy as np
import pytest

from rodcases import free_end, make_case

SOLVER = Path(__file__).resolve().parents[2] / "solver"

#: functions longer than 80 lines that are not compiled kernels, and why they stay
LONG_ALLOWED: set[str] = set()


def _modules() -> dict:
    mods = {}
    for f in SOLVER.rglob("*.py"):
        parts = list(f.relative_to(SOLVER.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = f
    return mods


def test_the_loop_is_short_and_no_function_is_long():
    assert len((SOLVER / "simulation.py").read_text().splitlines()) <= 400
    long = []
    for f in SOLVER.rglob("*.py"):
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                compiled = any("jit" in ast.unparse(d) for d in node.decorator_list)
                name = f"{f.relative_to(SOLVER.parent).as_posix()}:{node.name}"
                if node.end_lineno - node.lineno + 1 > 80 and not compiled \
                        and name not in LONG_ALLOWED:
                    long.append(name)
    assert not long, long


#: the most attributes one class of the solver may hold (issue 36)
MAX_ATTRIBUTES = 25


def _attributes(cls: ast.ClassDef) -> set:
    """Names a class assigns: every ``self.X`` it stores (plain, tuple-unpacked,
    augmented or annotated) in its methods. A dataclass's fields are not counted."""
    names = set()
    for fn in cls.body:
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)) or not fn.args.args:
            continue
        me = fn.args.args[0].arg
        for node in ast.walk(fn):
            if (isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store)
                    and isinstance(node.value, ast.Name) and node.value.id == me):
                names.add(node.attr)
    return names


def test_attribute_count_reads_stores_and_fields():
    cls = ast.parse("class A:\n    def f(self):\n        self.a, self.b = 1, 2\n"
                    "        self.c += 1\n        other.d = 3\n"
                    "    def g(me):\n        me.e: int = 4\n").body[0]
    assert _attributes(cls) == {"a", "b", "c", "e"}


def test_no_class_holds_more_than_25_attributes():
    big = {}
    for name, f in _modules().items():
        module = importlib.import_module(name)
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ClassDef) and not any(
                    "jitclass" in ast.unparse(d) for d in node.decorator_list):
                count = len(_attributes(node))
                if count > MAX_ATTRIBUTES:
                    big[f"{f.relative_to(SOLVER.parent).as_posix()}:{node.name}"] = count
    assert not big, big


def test_the_run_holds_its_parts_as_objects():
    """The step's parts as docs/developer.md draws them: the run holds its state, its step
    control and the step's assembly as objects of their own. No mixin base, and no
    property that forwards to another object (the run's ``Y`` was its state's, its
    ``h_next`` its step control's): callers read ``run.state.Y``, ``run.control.h_next``.
    The run of the centreline scheme offers the recorder the same names."""
    from solver.centreline_run import CentrelineRun
    from solver.run import RodRun
    from solver.state import RunState
    from solver.step_problem import ProblemAssembly
    from solver.stepping.control import StepControl

    for cls in (RodRun, CentrelineRun):
        assert cls.__bases__ == (object,), cls.__bases__
        forwards = [name for name, value in vars(cls).items() if not name.startswith("__")
                    and (isinstance(value, property) or hasattr(type(value), "__set__"))]
        assert not forwards, (cls.__name__, forwards)
    run = _run()
    assert isinstance(run.state, RunState) and isinstance(run.control, StepControl)
    assert isinstance(run.assembly, ProblemAssembly)
    for name in RunState.names() + ("h_next", "refusals", "last_dt", "seabed"):
        assert not hasattr(run, name), name


def _compiled_functions(tree) -> dict:
    """name -> whether numba inlines it into its callers (``inline="always"``), for the
    functions of a module's syntax tree decorated with numba.njit."""
    out = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef):
            for d in node.decorator_list:
                text = ast.unparse(d)
                if "njit" in text:
                    out[node.name] = "inline='always'" in text.replace('"', "'")
    return out


def _literal_argument_calls(trees: dict) -> list[str]:
    """Calls, inside compiled functions, of compiled functions numba does not inline,
    with True or False as an argument, or with a literal integer where another such call
    of the same function passes something else: numba compiles such a callee, and all it
    calls, once per literal (solver.banded.true_at_run_time, int_at_run_time)."""
    compiled = {}
    for tree in trees.values():
        compiled.update(_compiled_functions(tree))
    calls = []
    for path, tree in trees.items():
        for fn in ast.walk(tree):
            if not (isinstance(fn, ast.FunctionDef) and fn.name in compiled
                    and any("njit" in ast.unparse(d) for d in fn.decorator_list)):
                continue
            for call in ast.walk(fn):
                if not isinstance(call, ast.Call):
                    continue
                f = call.func
                name = f.id if isinstance(f, ast.Name) else getattr(f, "attr", None)
                if name in compiled and not compiled[name]:
                    calls.append((f"{path}:{call.lineno} {fn.name} -> {name}", name, call))

    def integer(a):
        if isinstance(a, ast.UnaryOp) and isinstance(a.op, ast.USub):
            a = a.operand
        return (isinstance(a, ast.Constant) and isinstance(a.value, int)
                and not isinstance(a.value, bool))

    # per callee and argument position, the argument texts its compiled callers pass
    passed = {}
    for _, name, call in calls:
        for k, a in enumerate(call.args):
            passed.setdefault((name, k), set()).add(ast.unparse(a))
    found = []
    for where, name, call in calls:
        args = list(call.args) + [k.value for k in call.keywords]
        if any(isinstance(a, ast.Constant) and isinstance(a.value, bool) for a in args) \
                or any(integer(a) and len(passed[(name, k)]) > 1
                       for k, a in enumerate(call.args)):
            found.append(where)
    return found


def test_compiled_functions_pass_no_literal_booleans_or_varying_integers():
    # the residual was compiled three times (want_jac True, False and run-time), a
    # third of a fresh installation's compile time (python -m benchmarks.compile_time)
    trees = {f.relative_to(SOLVER.parent).as_posix(): ast.parse(f.read_text())
             for f in SOLVER.rglob("*.py")}
    assert not _literal_argument_calls(trees), _literal_argument_calls(trees)
    # the check itself finds such a call, and leaves inlined callees and Python alone
    demo = ast.parse("@numba.njit\ndef g(a, w):\n    return a\n"
                     "@numba.njit(inline='always')\ndef h(a, w):\n    return a\n"
                     "@numba.njit(cache=True)\ndef f(a):\n    return g(a, True) + h(a, False)\n"
                     "def p(a):\n    return g(a, False)\n")
    assert _literal_argument_calls({"demo.py": demo}) == ["demo.py:9 f -> g"]
    # a literal integer counts where another compiled caller passes something else
    demo = ast.parse("@numba.njit\ndef g(a, k):\n    return a\n"
                     "@numba.njit\ndef f(a, j):\n    return g(a, -1) + g(a, j)\n"
                     "@numba.njit\ndef e(a):\n    return g(a, 3)\n")
    assert _literal_argument_calls({"demo.py": demo}) == ["demo.py:6 f -> g", "demo.py:9 e -> g"]
    demo = ast.parse("@numba.njit\ndef g(a, k):\n    return a\n"
                     "@numba.njit\ndef f(a):\n    return g(a, 0) + g(a, 0)\n")
    assert _literal_argument_calls({"demo.py": demo}) == []


def _run():
    from solver.run import RodRun

    load = [{"value": [0.0, 1.0, 0.0], "start": 0.0}]
    return RodRun(make_case(n_segments=6, dt=0.01, t_end=0.05, end=free_end(), forces=load))


def test_a_step_attempt_reports_acceptance_or_the_reason(monkeypatch):
    """try_step(h) from the state: accepted -> the state advanced, reason None; refused ->
    the state untouched (the same arrays), the reason named and counted nowhere else."""
    run = _run()
    ok = run.try_step(1e-6, restart=True)
    assert ok.ok and ok.reason is None and ok.iterations > 0
    assert run.state.t == 1e-6
    state = copy.copy(run.state)
    solve = run.newton.solve

    def failing(guess):
        Y, Fn, its, res, _, pose = solve(guess)
        return Y, Fn, its, np.inf, False, pose

    monkeypatch.setattr(run.newton, "solve", failing)
    refused = run.try_step(0.01)
    assert not refused.ok and refused.reason == "newton" and refused.nonfinite
    assert run.last_reject == "newton"
    assert run.state.t == state.t and run.state.Y is state.Y and run.state.q is state.q


@pytest.mark.parametrize("retry", [False, True])
def test_the_retry_after_a_newton_refusal_is_backward_euler_where_asked(monkeypatch, retry):
    """With numerics.backward_euler_retry the step after a Newton refusal (and after an
    energy refusal) is a backward-Euler step, which does not read the carried rates;
    without it, and after an accepted step either way, generalized-α's. An accepted
    attempt sets last_reject to None."""
    from solver.run import RodRun
    from solver.scheme import BACKWARD_EULER

    load = [{"value": [0.0, 1.0, 0.0], "start": 0.0}]
    case = make_case(n_segments=6, dt=0.01, t_end=0.05, end=free_end(), forces=load)
    case.numerics.backward_euler_retry = retry
    run = RodRun(case)
    assert run.try_step(1e-6, restart=True).ok and run.try_step(0.01).ok
    assert run.last_reject is None
    problem = run.assembly.step_problem
    alpha = problem(run.state, 0.01, after=run.last_reject).params
    assert alpha is not BACKWARD_EULER
    solve = run.newton.solve

    def failing(guess):
        Y, Fn, its, res, _, pose = solve(guess)
        return Y, Fn, its, 1.0, False, pose

    monkeypatch.setattr(run.newton, "solve", failing)
    assert run.try_step(0.01).reason == "newton"
    monkeypatch.setattr(run.newton, "solve", solve)
    prob = problem(run.state, 0.0025, after=run.last_reject)
    assert (prob.params is BACKWARD_EULER) == retry
    assert run.try_step(0.0025).ok and run.last_reject is None
    assert problem(run.state, 0.01, after=run.last_reject).params == alpha
    assert (problem(run.state, 0.0025, after="energy").params is BACKWARD_EULER) == retry
    assert problem(run.state, 0.0025, after="contact").params == alpha


def test_a_rolled_back_state_is_a_copy_that_serves_twice():
    """RodRun._state / _restore: the state after two restores of one snapshot is the
    snapshot's (the probe steps of step doubling restore the same snapshot twice)."""
    run = _run()
    run.try_step(1e-6, restart=True)
    saved = run._state()
    t0, Y0 = run.state.t, run.state.Y
    for _ in range(2):
        assert run.try_step(0.005).ok
        assert run.state.t > t0
        run._restore(saved)
        assert run.state.t == t0 and run.state.Y is Y0
