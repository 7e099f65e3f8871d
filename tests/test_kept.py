"""Traced programs kept across processes (jaxcal._kept): a kept program gives what jit gives, a
new store loads it without tracing, and whatever it cannot serve goes through plain jit."""

import concurrent.futures
import types

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxcal import _config, _kept

TRACES = []


class Scaled(eqx.Module):
    """An argument with a static field, like jaxcal's robots and layouts."""

    a: jax.Array
    kind: str = eqx.field(static=True)


def _fn(m: Scaled, x, *, power: int):
    TRACES.append(1)  # runs only while traced
    y = jnp.sin(m.a @ x) ** power
    return {"y": y, "model": Scaled(m.a * 2.0, m.kind + "!"), "n": power}


@pytest.fixture
def programs(tmp_path, monkeypatch):
    monkeypatch.setenv(_config.PROGRAMS_FOLDER, str(tmp_path))
    TRACES.clear()
    return tmp_path


def _args(seed=0):
    rng = np.random.default_rng(seed)
    return Scaled(rng.normal(size=(3, 3)), "k"), rng.normal(size=3)


def test_kept_program_matches_jit_and_a_new_store_does_not_trace(programs):
    m, x = _args()
    plain = eqx.filter_jit(_fn)(m, x, power=3)
    first = _config.jit(_fn, keep=True)(m, x, power=3)
    assert len(list(programs.iterdir())) == 1 and len(TRACES) == 2  # plain jit, then the export
    # a new process: a fresh function object, the program loaded from its file
    second = _config.jit(_fn, keep=True)(m, x, power=3)
    assert len(TRACES) == 2
    for out in (first, second):
        np.testing.assert_array_equal(out["y"], plain["y"])
        np.testing.assert_array_equal(out["model"].a, plain["model"].a)
        assert out["model"].kind == "k!" and out["n"] == 3


def test_the_key_follows_static_values_shapes_and_source(programs, monkeypatch):
    m, x = _args()
    f = _config.jit(_fn, keep=True)
    f(m, x, power=3)
    f(m, x, power=2)  # another static value
    f(m, x, power=3.0)  # equal, but another type
    f(Scaled(np.ones((4, 4)), "k"), np.ones(4), power=3)  # other shapes
    f(Scaled(m.a, "j"), x, power=3)  # another static field
    assert len(list(programs.iterdir())) == 5
    monkeypatch.setattr(_kept, "_environment", b"another jaxcal source")
    _config.jit(_fn, keep=True)(m, x, power=3)
    assert len(list(programs.iterdir())) == 6


def test_traced_arguments_go_through_jit(programs):
    m, x = _args()
    f = _config.jit(_fn, keep=True)
    xs = np.stack([x, 2 * x])
    batched = jax.vmap(lambda xi: f(m, xi, power=3)["y"])(xs)
    np.testing.assert_allclose(batched[1], eqx.filter_jit(_fn)(m, xs[1], power=3)["y"], rtol=1e-14)
    assert not list(programs.iterdir())


def test_a_damaged_file_is_traced_again_and_replaced(programs):
    m, x = _args()
    expected = _config.jit(_fn, keep=True)(m, x, power=3)["y"]
    (path,) = programs.iterdir()
    path.write_bytes(b"not a program")
    again = _config.jit(_fn, keep=True)(m, x, power=3)["y"]
    np.testing.assert_array_equal(again, expected)
    assert path.read_bytes() != b"not a program"


def test_off_with_the_cache_switch(programs, monkeypatch):
    monkeypatch.setenv(_config.CACHE_SWITCH, "0")
    m, x = _args()
    _config.jit(_fn, keep=True)(m, x, power=3)
    assert _config.programs_folder() is None and not list(programs.iterdir())


def test_a_prepared_program_is_traced_once_and_gives_what_jit_gives(programs):
    m, x = _args()
    plain = eqx.filter_jit(_fn)(m, x, power=3)
    TRACES.clear()
    f = _config.jit(_fn, keep=True)
    # only shapes and static values matter to prepare: zeros stand in for the data
    assert f.prepare(Scaled(np.zeros((3, 3)), "k"), np.zeros(3), power=3)
    assert not f.prepare(Scaled(np.zeros((3, 3)), "k"), np.zeros(3), power=3)  # already under way
    out = f(m, x, power=3)
    assert len(TRACES) == 1 and len(list(programs.iterdir())) == 1
    np.testing.assert_array_equal(out["y"], plain["y"])
    np.testing.assert_array_equal(out["model"].a, plain["model"].a)
    assert out["model"].kind == "k!" and out["n"] == 3
    # another static value is another program: prepared for one, the call traces its own
    f.prepare(Scaled(np.zeros((3, 3)), "k"), np.zeros(3), power=2)
    f(m, x, power=4)
    assert len(TRACES) == 3


def test_a_failed_preparation_leaves_the_call_to_jit(programs, monkeypatch):
    m, x = _args()

    def broken(*a):
        raise RuntimeError("the background thread failed")

    monkeypatch.setattr(_kept.Store, "_compiled", staticmethod(broken))
    f = _config.jit(_fn, keep=True)
    assert f.prepare(m, x, power=3)
    np.testing.assert_array_equal(f(m, x, power=3)["y"], eqx.filter_jit(_fn)(m, x, power=3)["y"])


def test_nothing_is_prepared_with_the_cache_off(programs, monkeypatch):
    monkeypatch.setenv(_config.CACHE_SWITCH, "0")
    m, x = _args()
    assert not _config.jit(_fn, keep=True).prepare(m, x, power=3)
    assert not _config.jit(_fn).prepare(m, x, power=3)  # not a kept function


def test_a_compile_under_way_in_a_parent_process_is_not_waited_for_after_a_fork(programs, monkeypatch):
    waited = []

    class Orphan(concurrent.futures.Future):  # its thread stayed in the parent: it would never end
        def result(self, timeout=None):
            waited.append(1)
            return None

    monkeypatch.setattr(_kept, "_compiler", lambda: types.SimpleNamespace(submit=lambda *a: Orphan()))
    m, x = _args()
    f = _config.jit(_fn, keep=True)
    assert f.prepare(m, x, power=3)
    _kept._forget_pool()  # what os.fork runs in the child
    np.testing.assert_array_equal(f(m, x, power=3)["y"], eqx.filter_jit(_fn)(m, x, power=3)["y"])
    assert not waited
