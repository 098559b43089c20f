"""``python -m service.cli``: the ``pdeanim`` console script."""

import sys

from service.cli import main

sys.exit(main())
