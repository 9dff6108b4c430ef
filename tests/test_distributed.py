"""Monte-Carlo over two processes on 127.0.0.1 (jax.distributed, gloo CPU collectives,
one CPU device each) with scripts/montecarlo_distributed.py: the same result as one
process, and bounded failures when a process never joins or dies."""

import json
import os
import pathlib
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest


ROOT = pathlib.Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "scripts" / "montecarlo_distributed.py"
# Small: 3 chunks of 8 draws (2 x 4 per device), 2 cables, 20 samples.
SMALL = ["--draws", "24", "--cables", "2", "--samples", "20", "--chunk-size", "8"]
SMALL += ["--method", "exact", "--deadline-s", "150"]
# Hard limit per process (a hang fails the test instead of blocking the suite).
HARD_S = 180
# jax's abort when the distributed service gives up (never joined, or a peer died).
FATAL = "JAX distributed service detected fatal errors"


def _runtime_missing():
    try:
        from jax._src.lib import _jax
    except ImportError as e:  # pragma: no cover - depends on the jaxlib
        return f"jaxlib has no _jax extension ({e})"
    if not hasattr(_jax, "make_gloo_tcp_collectives"):
        return "this jaxlib has no gloo CPU collectives (make_gloo_tcp_collectives)"
    return None


pytestmark = pytest.mark.skipif(
    _runtime_missing() is not None, reason=str(_runtime_missing())
)


def _port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _env():
    env = dict(os.environ)
    env["JAX_PLATFORMS"] = "cpu"
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    # One CPU device per process is set by --cpu-devices, not by leftover flags; the
    # suite's other XLA flags stay (tests/conftest.py).
    flags = env.pop("XLA_FLAGS", "").split()
    env["XLA_FLAGS"] = " ".join(f for f in flags if "device_count" not in f)
    for name in ("JAX_COORDINATOR_ADDRESS", "JAX_NUM_PROCESSES", "JAX_PROCESS_ID"):
        env.pop(name, None)
    return env


def _start(tmp, name, *args):
    err = open(tmp / f"{name}.err", "w")
    out = tmp / f"{name}.json"
    cmd = [sys.executable, str(SCRIPT), *SMALL, *args, "--out", str(out)]
    proc = subprocess.Popen(
        cmd, env=_env(), cwd=ROOT, stdout=err, stderr=err, stdin=subprocess.DEVNULL
    )
    proc.files = (err, out, tmp / f"{name}.err")
    return proc


def _finish(proc, timeout=HARD_S):
    err, out, log = proc.files
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        pytest.fail(f"no exit within {timeout} s: {log.read_text()[-3000:]}")
    finally:
        err.close()
    return proc.returncode, log.read_text(), out


def _peer(port, pid, *extra):
    return ["--coordinator", f"127.0.0.1:{port}", "--num-processes", "2"] + [
        "--process-id",
        str(pid),
        *extra,
    ]


def test_two_processes_equal_one_process(tmp_path):
    port = _port()
    procs = [_start(tmp_path, f"p{i}", *_peer(port, i)) for i in range(2)]
    # The single-process reference runs beside them, on 2 local devices: the same
    # per-device program as 2 processes of 1 device. (On 1 device the batch shape
    # differs and float32 rounding may too: observed 2.8e-9 m at 1.5e-2 m.)
    ref = _start(tmp_path, "ref", "--cpu-devices", "2")
    done = [_finish(p) for p in (*procs, ref)]
    for rc, log, _ in done:
        assert rc == 0, log[-3000:]
    # Process 0 writes the result; process 1 none.
    assert not done[1][2].exists()
    got, want = (json.loads(d[2].read_text()) for d in (done[0], done[2]))
    assert (got["process_count"], got["devices"], got["local_devices"]) == (2, 2, 1)
    assert (want["process_count"], want["devices"]) == (1, 2)
    assert got["method"] == want["method"] == "exact"
    assert got["status_counts"] == want["status_counts"]
    assert sum(got["status_counts"]["successful"]) > 0
    for counts in zip(*got["status_counts"].values()):
        assert sum(counts) == 24
    np.testing.assert_allclose(got["percentiles"], want["percentiles"], rtol=1e-12)


def test_a_process_that_never_joins_stops_the_other(tmp_path):
    # Only process 0 of 2 starts: it gives up after --timeout-s, not later.
    t0 = time.monotonic()
    proc = _start(tmp_path, "alone", *_peer(_port(), 0, "--timeout-s", "5"))
    rc, log, out = _finish(proc)
    elapsed = time.monotonic() - t0
    assert rc != 0 and rc != 3, log[-3000:]  # jax's abort, not the last guard
    assert FATAL in log and "DEADLINE_EXCEEDED" in log, log[-3000:]
    assert "waiting up to 5 s" in log
    assert not out.exists()
    # 5 s of waiting plus the interpreter's start (imports) on a loaded machine.
    assert elapsed < 5 + 60, elapsed


def test_a_process_that_dies_stops_the_other(tmp_path):
    port = _port()
    # Process 1 is killed once it has joined; process 0 is then waiting on it inside
    # the Monte-Carlo and must stop within the heartbeat timeout.
    extra = ("--heartbeat-s", "3")
    p0 = _start(tmp_path, "p0", *_peer(port, 0, *extra))
    p1 = _start(tmp_path, "p1", *_peer(port, 1, *extra))
    log1 = p1.files[2]
    t0 = time.monotonic()
    while "joined" not in log1.read_text():
        assert p1.poll() is None, log1.read_text()[-3000:]
        assert time.monotonic() - t0 < HARD_S, "process 1 never joined"
        time.sleep(0.1)
    p1.send_signal(signal.SIGKILL)
    killed = time.monotonic()
    _finish(p1)
    rc, log, out = _finish(p0)
    after = time.monotonic() - killed
    assert rc != 0 and rc != 3, log[-3000:]
    assert FATAL in log, log[-3000:]
    assert not out.exists()
    # 3 s heartbeat timeout plus the service's polling (observed ~6 s with 5 s).
    assert after < 3 + 30, after
