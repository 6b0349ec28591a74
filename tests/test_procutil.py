"""Worker processes end with their parent (ranad_core/procutil.py), as `ranad synth`'s render workers must."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from ranad_core.procutil import die_with_parent

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux only")

# A parent that starts a spawned pool worker (the way ranad synth does), prints the worker's pid, then waits.
PARENT = r"""
import multiprocessing as mp, os, sys, time
from concurrent.futures import ProcessPoolExecutor
from ranad_core.procutil import die_with_parent

def pid_then_sleep(with_guard):
    if with_guard:
        die_with_parent()
    print(os.getpid(), flush=True)
    time.sleep(60)

if __name__ == "__main__":
    pool = ProcessPoolExecutor(1, mp_context=mp.get_context("spawn"))
    pool.submit(pid_then_sleep, sys.argv[1] == "1")
    time.sleep(60)
"""


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(") ")[-1][0] != "Z"  # a zombie has ended
    except FileNotFoundError:
        return False


def _worker_after_parent_killed(tmp_path, with_guard: bool) -> int:
    script = tmp_path / "parent.py"
    script.write_text(PARENT)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.getcwd()] + sys.path))
    parent = subprocess.Popen([sys.executable, str(script), "1" if with_guard else "0"], stdout=subprocess.PIPE,
                              text=True, env=env, cwd=tmp_path)
    worker = int(parent.stdout.readline())
    parent.kill()  # SIGKILL: no cleanup of its own can run
    parent.wait()
    return worker


def test_worker_ends_when_parent_is_killed(tmp_path):
    worker = _worker_after_parent_killed(tmp_path, with_guard=True)
    deadline = time.time() + 10
    while _alive(worker) and time.time() < deadline:
        time.sleep(0.05)
    assert not _alive(worker)


def test_without_the_guard_the_worker_outlives_its_parent(tmp_path):
    """The control: what ranad synth's workers did before die_with_parent."""
    worker = _worker_after_parent_killed(tmp_path, with_guard=False)
    try:
        time.sleep(1.0)
        assert _alive(worker)
    finally:
        os.kill(worker, signal.SIGKILL)


def test_returns_true_on_linux():
    # in this process the parent is pytest's runner (alive), so the call just registers the signal
    pid = os.fork()
    if pid == 0:
        os._exit(0 if die_with_parent() else 3)
    _, status = os.waitpid(pid, 0)
    assert os.WEXITSTATUS(status) == 0
