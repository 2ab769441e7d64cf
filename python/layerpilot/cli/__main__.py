"""``python -m layerpilot.cli``: how `layerpilot up` and the tests start a node process."""

import sys

from layerpilot.cli import main

sys.exit(main())
