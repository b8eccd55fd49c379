"""`python -m parallel_eplus.cli`."""

import sys

from parallel_eplus.cli import main

sys.exit(main())
