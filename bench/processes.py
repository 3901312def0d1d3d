"""Starting pibr's server, relay and client as separate processes on loopback.

Used by ``pibr demo``, the benchmarks and the integration tests: each process runs
``python -m pibr ...``; the server and relay listen on port 0 and announce the port they got
on stdout ("pibr serve: listening on HOST:PORT"), so runs never collide on ports. Output of
every process goes to a log file; the last lines are shown when a process fails.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections import deque

from pibr.common.child_setup import CHILD_CPUS_ENV, child_env
from pibr.protocol.errors import PibrError

_LISTENING = re.compile(r"listening on (\S+):(\d+)")
_PROGRESS = re.compile(r"^PROGRESS (\d+) (\d+)")


class ProcessFailed(PibrError):
    pass


def free_port() -> int:
    """A TCP port free on loopback now (for a child to bind a moment later)."""
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def chromium_path() -> str | None:
    """The Chromium that drives pages in tests and ``pibr bench live``: ``$PIBR_CHROMIUM``, else
    ``chromium`` (Debian's package) or ``chromium-browser`` on PATH; None when there is none."""
    import shutil

    return os.environ.get("PIBR_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")


class PibrProcess:
    """One ``python -m pibr ARGS`` child with its output pumped to ``log_path``."""

    def __init__(self, name: str, args: list[str], log_path: str, on_progress=None, env=None, cpus=None):
        """cpus: the CPU numbers the child may run on (None: any), as if it had a machine of
        that many cores: its software rasteriser then starts as many threads."""
        self.name, self.args, self.log_path = name, args, log_path
        os.makedirs(os.path.dirname(log_path) or ".", exist_ok=True)
        self._log = open(log_path, "w")
        self.endpoint: tuple[str, int] | None = None
        self._listening = threading.Event()
        self._tail: deque[str] = deque(maxlen=30)
        self._on_progress = on_progress
        full_env = dict(os.environ, PYTHONUNBUFFERED="1", **(env or {}))
        # Ctrl-C and the CPUs set by the child itself (common/child_setup.py), not by a preexec_fn
        full_env.pop(CHILD_CPUS_ENV, None)
        full_env.update(child_env(cpus))
        if cpus is not None:
            cpus = sorted(cpus)
            full_env["LP_NUM_THREADS"] = str(len(cpus))      # llvmpipe's rasteriser threads
        self.cpus = cpus
        self.proc = subprocess.Popen([sys.executable, "-m", "pibr", *args], stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, bufsize=1, env=full_env)
        self._pump = threading.Thread(target=self._read, name=f"{name}-output", daemon=True)
        self._pump.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            m = _PROGRESS.match(line)
            if m:
                if self._on_progress is not None:
                    self._on_progress(int(m.group(1)), int(m.group(2)))
                continue
            self._log.write(line)
            self._log.flush()
            self._tail.append(line.rstrip())
            m = _LISTENING.search(line)
            if m and not self._listening.is_set():
                self.endpoint = (m.group(1), int(m.group(2)))
                self._listening.set()
        self._listening.set()

    def cpu_seconds(self) -> float | None:
        """CPU time the child has used so far, user + system, all its threads (None where
        /proc is not there, or once it has exited)."""
        try:
            with open(f"/proc/{self.proc.pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            return None
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")   # utime, stime

    def tail(self) -> str:
        return "\n".join(self._tail)

    def wait_listening(self, timeout: float = 120.0) -> tuple[str, int]:
        """-> the (host, port) the child announced. Raises at once when the child exits before
        announcing one (its output ends), with its exit code and last output."""
        if not self._listening.wait(timeout):
            raise ProcessFailed(f"{self.name} did not announce a port within {timeout:.0f} s; "
                                f"its last output:\n{self.tail()}")
        if self.endpoint is not None:
            return self.endpoint
        try:                             # its output ended: it has exited or is about to
            code = self.proc.wait(5)
        except subprocess.TimeoutExpired:
            raise ProcessFailed(f"{self.name} closed its output without announcing a port; "
                                f"its last output:\n{self.tail()}") from None
        raise ProcessFailed(f"{self.name} exited with code {code} before it announced a port; "
                            f"its last output:\n{self.tail()}")

    def wait(self, timeout: float | None = None) -> int:
        try:
            code = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            raise ProcessFailed(f"{self.name} did not finish within {timeout:.0f} s; last output:\n{self.tail()}") \
                from None
        self._pump.join(5)
        return code

    def stop(self, timeout: float = 10.0) -> None:
        """Ask to stop (SIGINT, as Ctrl-C), then terminate, then kill."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.terminate()
                try:
                    self.proc.wait(5)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait()
        self._pump.join(5)
        self._log.close()


def run_pipeline(out_dir: str, server_args: list[str], relay_args: list[str] | None, client_args: list[str],
                 on_progress=None, timeout: float = 1800.0) -> dict:
    """Start server (and relay), run the client to completion, stop the rest. -> timings in seconds."""
    return run_sessions(out_dir, server_args, relay_args, [client_args], on_progress=on_progress, timeout=timeout)


#: Where ``pibr bench realtime --placement`` runs each process: ``split`` gives the server and
#: the relay one core and the clients the other, standing in for a server and a headset on
#: separate machines; ``shared`` lets every process run anywhere.
PLACEMENTS = ("split", "shared")


def placement_cpus(placement: str) -> dict:
    """-> {"server": cpus, "relay": cpus, "client": cpus} (None: anywhere) for a placement."""
    if placement == "shared":
        return {"server": None, "relay": None, "client": None}
    if placement != "split":
        raise ValueError(f"placement must be one of {', '.join(PLACEMENTS)}, got {placement!r}")
    available = sorted(os.sched_getaffinity(0))
    if len(available) < 2:
        raise PibrError(f"--placement split needs two cores; this process may use only {available}")
    return {"server": {available[0]}, "relay": {available[0]}, "client": {available[1]}}


def run_sessions(out_dir: str, server_args: list[str], relay_args: list[str] | None, clients: list[list[str]],
                 on_progress=None, timeout: float = 1800.0, on_started=None, before_stop=None,
                 verbose_server: bool = False, placement: str = "shared") -> dict:
    """Start a server (and a relay in front of it), run every client (each a list of extra
    arguments) at once to completion, stop the rest. -> timings in seconds.

    A single client writes to ``out_dir``, several to ``out_dir/client-K``; logs go to
    ``out_dir/logs``. ``on_progress(done, total)`` hears the first client's ticks;
    ``on_started(processes)`` is called once every process runs, ``before_stop(processes)`` once
    the clients have ended and before the server and relay are stopped (processes: name ->
    PibrProcess). ``verbose_server`` logs the server's sessions (INFO) to its log; ``placement``:
    which cores each process may use (:data:`PLACEMENTS`)."""
    cpus = placement_cpus(placement)
    logs = os.path.join(out_dir, "logs")
    t0 = time.perf_counter()
    procs = []
    try:
        server = PibrProcess("server", ["-v"] * verbose_server + ["serve", "--port", "0", *server_args],
                             os.path.join(logs, "server.log"), cpus=cpus["server"])
        procs.append(server)
        host, port = server.wait_listening()
        t_server = time.perf_counter()
        target = f"{host}:{port}"
        if relay_args is not None:
            relay = PibrProcess("relay", ["relay", "--listen", "127.0.0.1:0", "--upstream", target, *relay_args],
                                os.path.join(logs, "relay.log"), cpus=cpus["relay"])
            procs.append(relay)
            rh, rp = relay.wait_listening(30)
            target = f"{rh}:{rp}"
        runners = []
        for k, client_args in enumerate(clients):
            name = "client" if len(clients) == 1 else f"client-{k + 1}"
            out = out_dir if len(clients) == 1 else os.path.join(out_dir, name)
            runners.append(PibrProcess(name, ["client", "--connect", target, "--out", out, "--progress", "lines",
                                              *client_args], os.path.join(logs, f"{name}.log"),
                                       on_progress=on_progress if k == 0 else None, cpus=cpus["client"]))
        procs += runners
        if on_started is not None:
            on_started({p.name: p for p in procs})
        deadline = time.perf_counter() + timeout
        for client in runners:
            code = client.wait(max(1.0, deadline - time.perf_counter()))
            if code != 0:
                raise ProcessFailed(f"{client.name} exited with code {code}; its last output:\n{client.tail()}\n"
                                    f"server's last output:\n{server.tail()}")
        for p in procs[:len(procs) - len(runners)]:
            if p.proc.poll() is not None:
                raise ProcessFailed(f"{p.name} exited early with code {p.proc.returncode}:\n{p.tail()}")
        if before_stop is not None:
            before_stop({p.name: p for p in procs})
        return {"server_start_s": t_server - t0, "total_s": time.perf_counter() - t0}
    finally:
        for p in reversed(procs):
            p.stop()
