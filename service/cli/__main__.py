"""``python -m pdeanim_service.cli``: the ``pdeanim`` console script."""

import sys

from pdeanim_service.cli import main

sys.exit(main())
