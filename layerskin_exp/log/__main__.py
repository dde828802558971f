"""python -m layerskin_exp.log inspect FILE | recover IN OUT"""

import sys

from layerskin_exp.log.cli import main

sys.exit(main())
