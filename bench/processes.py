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

from pibr.protocol.errors import PibrError

_LISTENING = re.compile(r"listening on (\S+):(\d+)")
_PROGRESS = re.compile(r"^PROGRESS (\d+) (\d+)")


class ProcessFailed(PibrError):
    pass


class PibrProcess:
    """One ``python -m pibr ARGS`` child with its output pumped to ``log_path``."""

    def __init__(self, name: str, args: list[str], log_path: str, on_progress=None, env=None):
        self.name, self.args, self.log_path = name, args, log_path
        os.makedirs(os.path.dirname(log_path) or ".", exist_ok=True)
        self._log = open(log_path, "w")
        self.endpoint: tuple[str, int] | None = None
        self._listening = threading.Event()
        self._tail: deque[str] = deque(maxlen=30)
        self._on_progress = on_progress
        full_env = dict(os.environ, PYTHONUNBUFFERED="1", **(env or {}))
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
    logs = os.path.join(out_dir, "logs")
    t0 = time.perf_counter()
    procs = []
    try:
        server = PibrProcess("server", ["serve", "--port", "0", *server_args], os.path.join(logs, "server.log"))
        procs.append(server)
        host, port = server.wait_listening()
        t_server = time.perf_counter()
        target = f"{host}:{port}"
        if relay_args is not None:
            relay = PibrProcess("relay", ["relay", "--listen", "127.0.0.1:0", "--upstream", target, *relay_args],
                                os.path.join(logs, "relay.log"))
            procs.append(relay)
            rh, rp = relay.wait_listening(30)
            target = f"{rh}:{rp}"
        client = PibrProcess("client", ["client", "--connect", target, "--out", out_dir, "--progress", "lines",
                                        *client_args], os.path.join(logs, "client.log"), on_progress=on_progress)
        procs.append(client)
        code = client.wait(timeout)
        if code != 0:
            raise ProcessFailed(f"client exited with code {code}; its last output:\n{client.tail()}\n"
                                f"server's last output:\n{server.tail()}")
        for p in procs[:-1]:
            if p.proc.poll() is not None:
                raise ProcessFailed(f"{p.name} exited early with code {p.proc.returncode}:\n{p.tail()}")
        return {"server_start_s": t_server - t0, "total_s": time.perf_counter() - t0}
    finally:
        for p in reversed(procs):
            p.stop()
