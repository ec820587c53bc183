"""`python -m pfnav_harness` is the `pfnav-demo` command."""

import sys

from .cli import main

sys.exit(main())
