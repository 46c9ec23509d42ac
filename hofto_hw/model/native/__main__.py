"""``python -m hofto_hw.model.native``: build the native dynamics library now (once per machine;
the test session's start does the same, tests/conftest.py)."""

import sys

from hofto_hw.model.native.build import main

sys.exit(main())
