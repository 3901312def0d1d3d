import os
import signal
import sys


def _child_setup() -> None:
    """What a parent starting this process as its child asked for (bench/processes.py,
    CHILD_SIGINT_ENV and CHILD_CPUS_ENV), done here before any thread starts."""
    if os.environ.pop("PIBR_CHILD_SIGINT", None) == "1":
        signal.signal(signal.SIGINT, signal.default_int_handler)
    cpus = os.environ.pop("PIBR_CHILD_CPUS", None)
    if cpus:
        os.sched_setaffinity(0, {int(c) for c in cpus.split(",")})


_child_setup()

from pibr.cli import main  # noqa: E402  (after the set-up: importing it may start threads)

sys.exit(main())
