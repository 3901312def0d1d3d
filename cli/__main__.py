import sys

from pibr.cli import main

sys.exit(main())
