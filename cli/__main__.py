import sys

from pibr.common.child_setup import apply_child_setup

apply_child_setup()   # before anything that may start a thread (common/child_setup.py)

from pibr.cli import main  # noqa: E402

sys.exit(main())
