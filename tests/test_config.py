"""What importing jaxcal sets up (``jaxcal._config``): the persistent compilation cache (its
folder, the user's own settings, the switch that turns it off, a second process that compiles
nothing it has seen) and the quick-compile options."""

import json
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcal
from jaxcal import _config
from jaxcal.lie import rpy_to_matrix


@pytest.fixture
def jax_cache_settings():
    """The cache settings of this process, restored after the test (the suite's own cache is
    already in use, so changing them here compiles nothing elsewhere)."""
    keep = (jax.config.jax_compilation_cache_dir, jax.config.jax_persistent_cache_min_compile_time_secs)
    yield
    jax.config.update("jax_compilation_cache_dir", keep[0])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", keep[1])


def test_the_users_own_cache_is_kept(jax_cache_settings, monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv(_config.CACHE_SWITCH, raising=False)
    jax.config.update("jax_compilation_cache_dir", str(tmp_path / "mine"))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 2.5)
    assert _config.use_compilation_cache() == str(tmp_path / "mine")
    assert jax.config.jax_compilation_cache_dir == str(tmp_path / "mine")
    assert jax.config.jax_persistent_cache_min_compile_time_secs == 2.5
    assert not (tmp_path / "jaxcal").exists()


def test_the_cache_goes_in_the_users_cache_folder(jax_cache_settings, monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv(_config.CACHE_SWITCH, raising=False)
    monkeypatch.delenv("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", raising=False)
    jax.config.update("jax_compilation_cache_dir", None)
    folder = tmp_path / "jaxcal" / "xla"
    assert _config.use_compilation_cache() == str(folder)
    assert folder.is_dir() and jax.config.jax_compilation_cache_dir == str(folder)
    assert jax.config.jax_persistent_cache_min_compile_time_secs == _config.MIN_CACHED_COMPILE_S


@pytest.mark.parametrize("value", ["0", "off", "False"])
def test_the_switch_turns_the_cache_off(jax_cache_settings, monkeypatch, tmp_path, value):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setenv(_config.CACHE_SWITCH, value)
    jax.config.update("jax_compilation_cache_dir", None)
    assert _config.use_compilation_cache() is None
    assert jax.config.jax_compilation_cache_dir is None and not (tmp_path / "jaxcal").exists()


def test_an_unwritable_cache_folder_means_no_cache(jax_cache_settings, monkeypatch, tmp_path):
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "file"))  # a file where the folder would go
    jax.config.update("jax_compilation_cache_dir", None)
    assert _config.use_compilation_cache() is None
    assert jax.config.jax_compilation_cache_dir is None


def test_import_loads_only_what_every_use_needs():
    """Plots, URDF parsing, the command line, statistics and the solver library load on first
    use (a process that loads its kept programs never traces a solve)."""
    lazy = ("matplotlib", "yourdfpy", "trimesh", "rich", "typer", "scipy", "optimistix", "lineax")
    code = f"import sys, jaxcal; print([m for m in {lazy!r} if m in sys.modules])"
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stdout.strip() == "[]"


_CHILD = """
import json, logging
seen = {"hit": [], "miss": [], "quick": []}
class Log(logging.Handler):
    def emit(self, record):  # jax logs each persistent-cache lookup and skipped write at DEBUG level
        m = record.getMessage()
        if m.startswith("Persistent compilation cache hit for"):
            seen["hit"].append(m.split("'")[1])
        elif m.startswith("PERSISTENT COMPILATION CACHE MISS for"):
            seen["miss"].append(m.split("'")[1])
        elif m.startswith("Not writing persistent cache entry for") and "to compile" in m:
            seen["quick"].append(m.split("'")[1])
log = logging.getLogger("jax._src.compiler")
log.setLevel(logging.DEBUG)
log.addHandler(Log())
import numpy as np
import jaxcal
from jaxcal.calibration import _core
member = _core._member  # runs only while the solver is traced
traced = []
_core._member = lambda *a: traced.append(1) or member(*a)
robot = jaxcal.preset("paper-6r")
sim = jaxcal.simulate(robot, n_poses=30, seed=4, sigma_pos=0.02, tool=True)
for v in seen.values(): v.clear()
res = jaxcal.calibrate(robot, sim.q[0], sim.measured[0, :, :3, 3], estimate_base=False)
seen["x"] = np.asarray(res.x).tolist()
seen["traced"] = len(traced)
import sys
seen["solver_library"] = "optimistix" in sys.modules  # needed only to trace the solve
print(json.dumps(seen))
"""


def test_a_second_process_compiles_nothing_it_has_seen(tmp_path):
    """Two fresh processes with the user's cache folder (nothing configured): the first compiles
    the calibration's programs and keeps them, the second loads them and gets the same result."""
    # no cache settings of the suite's; its quick-compile settings kept (the same in both processes)
    quick = ("JAX_DISABLE_MOST_OPTIMIZATIONS", "JAX_TRACEBACK_IN_LOCATIONS_LIMIT")
    env = {
        k: v
        for k, v in os.environ.items()
        if (not k.startswith("JAX_") or k in quick) and k not in (_config.CACHE_SWITCH, _config.PROGRAMS_FOLDER)
    }
    env["XDG_CACHE_HOME"] = str(tmp_path)
    runs = []
    for _ in range(2):
        p = subprocess.run([sys.executable, "-c", _CHILD], capture_output=True, text=True, env=env, timeout=600)
        assert p.returncode == 0, p.stderr[-2000:]
        runs.append(json.loads(p.stdout.strip().splitlines()[-1]))
    first, second = runs
    ours = lambda names: set(n for n in names if n.startswith("jit__"))  # noqa: E731  (jaxcal's own programs)
    assert "jit__members" in ours(first["miss"]) and not first["hit"]
    # what the first kept, the second loads; it compiles again only what took the first less than
    # the cache's threshold to compile
    kept = ours(first["miss"]) - ours(first["quick"])
    assert "jit__members" in kept and kept <= ours(second["hit"])
    assert ours(second["miss"]) <= ours(first["quick"])
    np.testing.assert_array_equal(second["x"], first["x"])
    assert any((tmp_path / "jaxcal" / "xla").iterdir())
    # the traced programs are kept too: the second process traced none of them
    assert {p.name.split("-")[0].rsplit(".", 1)[1] for p in (tmp_path / "jaxcal" / "programs").iterdir()} >= {
        "_members",
        "_nominal",
    }
    assert first["traced"] and not second["traced"]
    assert first["solver_library"] and not second["solver_library"]


def test_quick_compile_options_are_known_and_change_no_result():
    """XLA accepts every quick-compile option (an option a new jaxlib dropped fails here), and a
    program compiled with them gives what the default compile gives."""

    def f(a, b):
        L = jnp.linalg.cholesky(a @ a.T + jnp.eye(a.shape[0]))
        return jnp.sin(b) @ L, jnp.tanh(a).sum(0)

    twice = _config.jit(f)
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(5, 5)), rng.normal(size=(3, 5))
    quick = twice(a, b)
    full = twice(a, b, quick=False)
    compiled = jax.jit(f, compiler_options=_config.QUICK_COMPILE).lower(a, b).compile()
    for u, v, w in zip(quick, full, compiled(a, b)):
        np.testing.assert_allclose(np.asarray(u), np.asarray(v), rtol=1e-13, atol=1e-14)
        np.testing.assert_array_equal(np.asarray(u), np.asarray(w))


def test_loading_a_robot_file_compiles_nothing(tmp_path):
    """A robot file is read with NumPy: no JAX program is compiled for it (each would cost a
    compile in a fresh process)."""
    frames = []
    for rpy, xyz in (([0.1, -0.2, 0.3], [1.0, 2.0, 3.0]), ([-0.4, 0.5, 2.9], [500.0, -20.0, 10.0])):
        T = np.eye(4)
        T[:3, :3] = rpy_to_matrix(np.array(rpy))
        T[:3, 3] = xyz
        frames.append(T)
    panda = jaxcal.preset("panda")
    robot = jaxcal.Robot(np.asarray(panda.dh), convention="mdh", tool=frames[0], base=frames[1], name="rotated")
    path = tmp_path / "r.toml"
    jaxcal.save_robot(robot, path)
    compiled = []

    def on(event, duration, **kw):
        if event == "/jax/core/compile/backend_compile_duration":
            compiled.append(kw.get("fun_name", ""))

    jax.monitoring.register_event_duration_secs_listener(on)
    try:
        loaded = jaxcal.load_robot(path)
        jaxcal.save_robot(loaded, tmp_path / "again.toml")
    finally:
        jax.monitoring.unregister_event_duration_listener(on)
    assert compiled == []
    np.testing.assert_allclose(np.asarray(loaded.tool), frames[0], atol=1e-12)
    np.testing.assert_allclose(np.asarray(loaded.base), frames[1], atol=1e-12)


def test_objects_frozen_at_exit():
    """The exit handler freezes what is alive, so the interpreter's last collections skip it."""
    code = "import atexit, gc, jaxcal; atexit._run_exitfuncs(); print(gc.get_freeze_count())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert int(out.stdout.split()[-1]) > 10_000
