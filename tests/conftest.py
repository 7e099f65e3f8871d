import os
from pathlib import Path

# One persistent XLA compilation cache for the whole run, shared by the xdist workers and the
# subprocesses the tests start (CLI, notebooks, benchmarks): the same solvers are compiled
# once instead of once per process. Set before jax is imported; an existing setting wins.
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(Path(__file__).resolve().parent.parent / ".pytest_cache" / "jax-cache"))
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.2")

import jax  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxcal  # noqa: F401  (enables float64)

jax.config.update("jax_enable_x64", True)


@pytest.fixture
def rng():
    return np.random.default_rng(20221)


def random_dh(rng, n=6, *, lengths=300.0):
    """A random, generic DH table (mm, rad)."""
    return np.c_[rng.uniform(-np.pi, np.pi, n), rng.uniform(-lengths, lengths, n),
                 rng.uniform(-lengths, lengths, n), rng.uniform(-np.pi, np.pi, n)]


def random_transform(rng, scale=100.0):
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    T[:3, 3] = rng.normal(size=3) * scale
    return T


def run_cli(monkeypatch, capsys, *args):
    """`jaxcal ARGS` in-process through the real entry point `jaxcal.cli.main`; returns
    (exit code, stdout, stderr)."""
    import sys

    from jaxcal.cli import main

    monkeypatch.setattr(sys, "argv", ["jaxcal", *map(str, args)])
    with pytest.raises(SystemExit) as e:
        main()
    out = capsys.readouterr()
    return e.value.code, out.out, out.err
