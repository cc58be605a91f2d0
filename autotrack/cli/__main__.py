import sys

from autotrack.cli import main

sys.exit(main())
