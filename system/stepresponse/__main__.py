"""``python -m robofmu.system.stepresponse ...``: the ``robofmu step`` command on its own."""
import sys

from .cli import main

sys.exit(main())
