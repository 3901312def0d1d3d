"""The children bench/processes.py starts: their CPUs and Ctrl-C set by the child itself at start-up
(common/child_setup.py, from cli/__main__.py), not by Python code run between fork and exec, which can deadlock a parent with
threads."""
import os
import signal
import subprocess

import pytest

from pibr.bench.processes import PibrProcess
from pibr.common.child_setup import CHILD_CPUS_ENV

pytestmark = pytest.mark.integration


def _relay(tmp_path, cpus=None) -> PibrProcess:
    # a relay needs no scene nor GL; its upstream is dialled only when a client comes
    return PibrProcess("relay", ["relay", "--listen", "127.0.0.1:0", "--upstream", "127.0.0.1:9"],
                       str(tmp_path / "relay.log"), cpus=cpus)


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity"), reason="no CPU affinity on this platform")
def test_a_child_runs_on_the_cpus_it_was_given(tmp_path):
    cpu = min(os.sched_getaffinity(0))
    relay = _relay(tmp_path, cpus=[cpu])
    try:
        relay.wait_listening(60)
        assert os.sched_getaffinity(relay.proc.pid) == {cpu}
        # (its environment as it started: what its rasteriser reads)
        environ = open(f"/proc/{relay.proc.pid}/environ", "rb").read().split(b"\0")
        assert b"LP_NUM_THREADS=1" in environ and f"{CHILD_CPUS_ENV}={cpu}".encode() in environ
    finally:
        relay.stop()


def test_ctrl_c_stops_a_child_started_by_a_parent_that_ignores_it(tmp_path):
    before = signal.signal(signal.SIGINT, signal.SIG_IGN)   # as a background job of a script
    try:
        relay = _relay(tmp_path)
    finally:
        signal.signal(signal.SIGINT, before)
    try:
        relay.wait_listening(60)
        relay.proc.send_signal(signal.SIGINT)
        try:
            code = relay.proc.wait(20)
        except subprocess.TimeoutExpired:
            pytest.fail("the child ignored SIGINT, inherited from its parent")
        assert code != -signal.SIGKILL
    finally:
        relay.stop()
