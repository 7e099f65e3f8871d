"""Robots shared over devices give the results of one device. Two subprocesses (the device count
is fixed when JAX starts) of two CPU devices each, joined by jax.distributed, check 1, 2 and 4
devices at once; timeouts make sure nothing can hang."""

import json
import os
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from jaxcal.errors import DataError
from jaxcal.sharding import select_devices

ROOT = Path(__file__).resolve().parents[2]
DATA = """
import json, numpy as np, jaxcal
robot = jaxcal.preset("paper-6r")
sim = jaxcal.simulate(robot, n_robots=8, n_poses=12, seed=5, sigma_pos=0.02, sigma_rot=2e-5)
kw = dict(estimate_base=False, estimate_tool=False, sigma_pos_mm=0.02, sigma_rot_rad=2e-5)
def fit(devices):
    return jaxcal.calibrate_batch(robot, sim.q, sim.measured, devices=devices, **kw)
"""


def _run(code: str, *args, env=None, timeout: float = 240):
    env = dict(os.environ, PYTHONPATH=str(ROOT), **(env or {}))
    return subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(code), *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=ROOT,
    )


def _result(p, timeout: float = 240) -> dict:
    try:
        out, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.kill()
        out, err = p.communicate()
        pytest.fail(f"subprocess timed out:\n{err[-3000:]}")
    assert p.returncode == 0, err[-3000:]
    return json.loads(out.strip().splitlines()[-1])


CHILD = (
    """
import sys, jax
pid, port = int(sys.argv[1]), int(sys.argv[2])
jax.config.update("jax_num_cpu_devices", 2)
jax.config.update("jax_cpu_collectives_implementation", "gloo")
jax.distributed.initialize(f"localhost:{port}", num_processes=2, process_id=pid, initialization_timeout=60)
"""
    + DATA.replace("n_robots=8, n_poses=12", "n_robots=128, n_poses=30").replace(
        "kw = dict(estimate_base=False, estimate_tool=False, ", "kw = dict("
    )
    + """
ref = fit(None)  # this process's first device alone
out = {"pid": pid, "ref": list(ref.devices)}
for n in (2, 4):  # one device of each process; all four
    r = fit(n)
    out[n] = {"devices": list(r.devices), "diff": float(np.abs(r.x - ref.x).max()), "ok": bool(r.converged.all())}
print(json.dumps(out))
jax.distributed.shutdown()
"""
)


def _processes(devices) -> list[str]:
    return [d.split("(process ")[1].rstrip(")") for d in devices]


def test_one_two_four_devices_over_two_processes_give_the_same_results():
    """Two processes of two CPU devices each, joined by jax.distributed on localhost: the fits on
    1 device (each process alone), 2 (one per process) and 4 agree to 1e-12, and name the devices
    they used. 128 robots of 30 poses, base and tool estimated, where a solve sharded over two CPU
    devices of each process deadlocks: each process solves its own devices' shares in turn, then
    gathers."""
    with socket.socket() as s:  # a free port for the coordinator
        s.bind(("localhost", 0))
        port = s.getsockname()[1]
    # the device count comes from jax_num_cpu_devices: no forced count from XLA_FLAGS, only
    # conftest's compile-time flags
    flags = " ".join(f for f in os.environ.get("XLA_FLAGS", "").split() if "device_count" not in f)
    procs = [_run(CHILD, pid, port, env={"XLA_FLAGS": flags}) for pid in (0, 1)]
    try:
        results = [_result(p) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    for pid, r in enumerate(results):
        assert r["pid"] == pid and _processes(r["ref"]) == [str(pid)]
        assert _processes(r["2"]["devices"]) == ["0", "1"]
        assert _processes(r["4"]["devices"]) == ["0", "0", "1", "1"]
        for n in ("2", "4"):
            assert r[n]["ok"] and r[n]["diff"] < 1e-12, r


def test_too_many_devices_is_a_clear_error():
    with pytest.raises(DataError, match=r"devices: 3 requested, but 1 cpu device is available"):
        select_devices(3)
    for bad in ("two", 0, -1, 1.5):
        with pytest.raises(DataError, match="devices must be 'all' or a positive integer"):
            select_devices(bad)


ONE_PROCESS = """
import json, jax, numpy as np, jaxcal
jax.config.update("jax_num_cpu_devices", 2)
robot = jaxcal.preset("paper-6r")
sim = jaxcal.simulate(robot, n_robots=32, n_poses=30, seed=3, sigma_pos=0.02, sigma_rot=2e-5)
two = jaxcal.calibrate_batch(robot, sim.q, sim.measured, devices="all")  # base and tool estimated
one = jaxcal.calibrate_batch(robot, sim.q, sim.measured, devices=None)
print(json.dumps({"devices": list(two.devices), "diff": float(np.abs(two.x - one.x).max())}))
"""


def test_two_cpu_devices_of_one_process_finish_where_a_sharded_solve_deadlocked():
    """32 robots with base and tool estimated over two CPU devices of one process, where a sharded
    solve (or the kept programs run on both devices at once) deadlocks: each device solves its own
    members in turn."""
    flags = " ".join(f for f in os.environ.get("XLA_FLAGS", "").split() if "device_count" not in f)
    r = _result(_run(ONE_PROCESS, env={"XLA_FLAGS": flags}), timeout=150)
    assert len(r["devices"]) == 2 and r["diff"] < 1e-12
