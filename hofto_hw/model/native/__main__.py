"""``python -m hofto_hw.model.native``: build the native dynamics library now (once per machine;
CI runs it before the tests so that no test waits for the compiler)."""

import sys

from hofto_hw.model.native.build import main

sys.exit(main())
