"""The benchmarks' one timing helper, built on :func:`jaxcal.experiments.timed`: the first call
(compile + run) apart from the warm calls, their median, and the machine they ran on."""

from __future__ import annotations

import statistics

from jaxcal.experiments import machine_info, summary  # noqa: F401  (re-exported)
from jaxcal.experiments import timed as _timed

machine = machine_info


def describe() -> str:
    """The machine in one line: CPU model, cores, device, versions."""
    m = machine_info()
    flags = f", XLA_FLAGS={m['xla_flags']!r}" if m["xla_flags"] else ""
    return (
        f"{m['cpu']}, {m['cores']} cores, device {m['device']} ({m['platform']}), jax {m['jax']}, "
        f"python {m['python']}{flags}"
    )


def print_machine() -> None:
    print("machine:", describe(), flush=True)


def timed(fn, *args, repeats: int = 7, budget_s: float | None = None, result: bool = False):
    """``(first call seconds, [warm call seconds])`` of ``fn(*args)`` (results blocked on), and
    with ``result`` the first call's result in front: ``(result, first, runs)``.

    ``repeats`` warm calls; with ``budget_s``, as many as fit in that time judged by the first
    warm call, at least 3 and at most ``repeats``, and a single one when a call takes over 2 s
    (a sweep over sizes then spends its time where the noise is).
    """
    call = lambda: fn(*args)
    out, first, runs = _timed(call, 1)
    n = repeats
    if budget_s is not None:
        n = 1 if runs[0] > 2.0 else int(min(max(budget_s / runs[0], 3), repeats))
    if n > 1:  # every call from here on is warm: the helper's "first" is one more run
        _, again, more = _timed(call, n - 2)
        runs += [again] + more
    return (out, first, runs) if result else (first, runs)


def compile_text(first: float, runs) -> str:
    """Compile time read off a first call: the first call minus the warm median; when the warm
    calls spread more than that difference, it is below the timing noise and the text says so."""
    med = statistics.median(runs)
    c = first - med
    spread = max(runs) - min(runs)
    if c <= spread:
        return f"first call {first:.2f} s (compile below the warm spread, {spread:.2f} s)"
    return f"compile {c:.2f} s"


def compile_s(first: float, runs) -> float:
    """First call minus the warm median, at least 0."""
    return max(first - statistics.median(runs), 0.0)
