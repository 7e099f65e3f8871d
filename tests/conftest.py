import os
from pathlib import Path

# One persistent XLA compilation cache for the whole run, shared by the xdist workers and the
# subprocesses the tests start (CLI, benchmarks): the same solvers are compiled once instead of
# once per process. Set before jax is imported; an existing setting wins.
_CACHE = Path(__file__).resolve().parent.parent / ".pytest_cache" / "jax-cache"
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(_CACHE))
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
# jaxcal's traced programs kept beside it, as a user's are beside jaxcal's own cache
os.environ.setdefault("JAXCAL_PROGRAMS", str(_CACHE.parent / "jaxcal-programs"))
# The suite is compile-bound (small data, many distinct programs): XLA without most of its
# optimisations compiles about twice as fast, and the tests check values, not speed
# (benchmarks/ measures speed with the default compiler).
os.environ.setdefault("JAX_DISABLE_MOST_OPTIMIZATIONS", "1")
# No Python traceback in the source locations of the programs' operations (100 frames each by
# default): lowering writes less, and no test reads them (Python's own tracebacks are unchanged).
os.environ.setdefault("JAX_TRACEBACK_IN_LOCATIONS_LIMIT", "0")
# XLA CPU's older loop emitters compile these programs about twice as fast as its fusion
# emitters (and run them slower, which the tests do not mind); not for benchmarks or the CLI.
# One LLVM module per program instead of several compiled in parallel: the two xdist workers
# already use both cores, and the split itself costs compile time (about a sixth here).
for _flag in ("--xla_cpu_use_fusion_emitters=false", "--xla_cpu_parallel_codegen_split_count=1"):
    if _flag.split("=")[0] not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " " + _flag).strip()

import jax  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxcal  # noqa: F401,E402  (enables float64)

jax.config.update("jax_enable_x64", True)


@pytest.fixture
def rng():
    return np.random.default_rng(20221)


# JAXCAL_COMPILE_LOG=path: append each test's compile seconds (trace, lower, XLA) to that file, to
# find the tests whose compiles dominate a run with an empty compilation cache.
if os.environ.get("JAXCAL_COMPILE_LOG"):
    import jax.monitoring

    _compile = {"s": 0.0, "n": 0}

    def _on_event(event, duration, **_):
        if event.startswith("/jax/core/compile/"):
            _compile["s"] += duration
            _compile["n"] += event.endswith("backend_compile_duration")

    jax.monitoring.register_event_duration_secs_listener(_on_event)

    @pytest.fixture(autouse=True)
    def _log_compiles(request):
        import time

        _compile.update(s=0.0, n=0)
        t0 = time.perf_counter()
        yield
        with open(os.environ["JAXCAL_COMPILE_LOG"], "a") as f:
            f.write(f"{_compile['s']:.2f} {_compile['n']} {time.perf_counter() - t0:.2f} {request.node.nodeid}\n")


@pytest.hookimpl
def pytest_cmdline_main(config):
    """``-n N`` distributes by work stealing: the suite has a few tests much longer than the rest,
    and a worker that is done early takes tests from the other instead of waiting."""
    if getattr(config.option, "numprocesses", None) and getattr(config.option, "dist", None) == "load":
        config.option.dist = "worksteal"
