"""What a parent starting ``python -m pibr`` as its child (bench/processes.py) asks the child to
set itself at start-up, before any thread starts: Python code run between fork and exec
(``preexec_fn``) can deadlock a parent with threads (a soak's clients, started from threads, hung
at fork holding a lock another thread had). Light on purpose: cli/__main__.py imports it first."""
import os
import signal

#: ``1``: Ctrl-C (SIGINT) stops the child as from a terminal, even where its parent was started
#: ignoring it (a background job of a script ignores SIGINT, and children inherit that).
CHILD_SIGINT_ENV = "PIBR_CHILD_SIGINT"
#: The CPU numbers the child may run on, comma-separated.
CHILD_CPUS_ENV = "PIBR_CHILD_CPUS"


def child_env(cpus=None) -> dict:
    """The variables that ask a child for the default SIGINT and, with ``cpus``, those CPUs."""
    env = {CHILD_SIGINT_ENV: "1"}
    if cpus is not None:
        env[CHILD_CPUS_ENV] = ",".join(str(c) for c in sorted(cpus))
    return env


def apply_child_setup() -> None:
    """In the child: what :func:`child_env` asked for (the variables are taken out of the environment,
    so the child's own children do not inherit them)."""
    if os.environ.pop(CHILD_SIGINT_ENV, None) == "1":
        signal.signal(signal.SIGINT, signal.default_int_handler)
    cpus = os.environ.pop(CHILD_CPUS_ENV, None)
    if cpus:
        os.sched_setaffinity(0, {int(c) for c in cpus.split(",")})
